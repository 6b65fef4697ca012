"""`teleprev collision`: data, training and grid search for the learned self-collision correction (CPN + CCN)."""

from __future__ import annotations

import math
import shlex
from pathlib import Path

import typer

app = typer.Typer(
    help="Learned self-collision correction: generate labelled data, train the CPN and CCN, grid-search the CCN loss.",
    no_args_is_help=True,
)

ROBOT = typer.Option("leap_hand_right", "--robot", "-r", help="A URDF file, or the name of one in urdf/.")
DEVICE = typer.Option("auto", help="Torch device for training: auto (a GPU if there is one), cpu, cuda, cuda:1 …")


def _command(ctx: typer.Context) -> str:
    """The command as given (only the options set on the command line), for the model card."""
    parts = ["teleprev", *ctx.command_path.split()[1:]]
    for param in ctx.command.params:
        source = ctx.get_parameter_source(param.name)
        if source is None or source.name != "COMMANDLINE":
            continue
        value = ctx.params[param.name]
        if param.param_type_name == "argument":
            parts.append(shlex.quote(str(value)))
        else:
            parts += [param.opts[0], shlex.quote(str(value))]
    return " ".join(parts)


def _floats(text: str, what: str) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise typer.BadParameter(f"{what}: expected comma-separated numbers, got {text!r}") from None
    if not values or any(not math.isfinite(v) or v < 0 for v in values):
        raise typer.BadParameter(f"{what}: expected one or more non-negative finite numbers, got {text!r}")
    return values


def _hidden(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(v) for v in text.split(",") if v.strip())
    except ValueError:
        raise typer.BadParameter(
            f"--hidden: expected comma-separated layer widths such as 256,256,256, got {text!r}"
        ) from None
    if not sizes or any(s <= 0 for s in sizes):
        raise typer.BadParameter(f"--hidden: layer widths must be positive, got {text!r}")
    return sizes


def check_training_paths(data: Path, out: Path) -> None:
    """A training command's dataset folder and the weights file it writes (its card goes beside it), before
    torch loads: one line each."""
    from teleprev.cli.outputs import check_input, check_output

    check_input(data, "DATA", "collision dataset folder", folder=True)
    check_output(out, "--out", make_parents=True)
    check_output(out.with_suffix(".md"), "--out", make_parents=True)


TORCH_DEVICES = ("cpu", "cuda", "mps", "xpu")  # --device: one of these, a GPU's with ":N", or auto


def check_device(device: str) -> None:
    """--device before torch loads (torch names a device it does not know only once training starts)."""
    from teleprev.errors import ConfigError

    kind, _, index = device.partition(":")
    if device != "auto" and not (kind in TORCH_DEVICES and (not index or (index.isdigit() and kind != "cpu"))):
        raise ConfigError(f"--device must be auto, {', '.join(TORCH_DEVICES)} or a GPU's with its number "
                          f"(cuda:1), got {device!r}")


def _setup(robot: str):
    from teleprev.errors import UrdfError
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    try:
        model = load_robot(robot)
    except UrdfError as exc:  # name the option: the URDF's own line names only the file
        raise UrdfError(str(exc), "--robot") from None
    return model, SelfCollisionChecker(model)


@app.command("dataset")
def dataset(
    out: Path = typer.Argument(..., help="Folder to write the parquet shards into (an interrupted run resumes)."),
    robot: str = ROBOT,
    uniform: int = typer.Option(
        600_000, "--uniform", "-u", min=0, help="Configurations sampled uniformly in the joint limits."
    ),
    boundary: int = typer.Option(
        600_000, "--boundary", "-b", min=0, help="Configurations near the collision boundary."
    ),
    seed: int = typer.Option(0, min=0, help="Random seed (shard k draws from (seed, k))."),
    shard_size: int = typer.Option(20_000, min=100, help="Configurations per shard file."),
    bisection_steps: int = typer.Option(8, min=1, max=30, help="Bisection steps towards the boundary."),
    jitter_per_pair: int = typer.Option(2, min=0, help="Jittered copies around each boundary point."),
    jitter_min: float = typer.Option(0.005, min=0.0, help="Smallest jitter (rad, per joint standard deviation)."),
    jitter_max: float = typer.Option(0.1, min=0.0, help="Largest jitter (rad)."),
    workers: int = typer.Option(0, min=0, help="Worker processes (0: one per core)."),
) -> None:
    """Sample configurations, label every link with the exact checker, and write parquet shards."""
    from teleprev.cli.outputs import check_output
    from teleprev.cli.values import check_finite

    check_output(out, "OUT", "folder", make_parents=True)
    for option, value in (("--jitter-min", jitter_min), ("--jitter-max", jitter_max)):
        check_finite(option, value, "a finite jitter in radians (0 or more)")
    import os
    import time

    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    from teleprev.noncollision.dataset import DatasetSettings, generate, pending_shards, prepare
    from teleprev.noncollision.sampling import BoundarySettings

    if uniform + boundary == 0:
        raise typer.BadParameter("nothing to generate: --uniform and --boundary are both 0")
    if boundary and jitter_min > jitter_max:
        raise typer.BadParameter(f"--jitter-min {jitter_min} is larger than --jitter-max {jitter_max}")
    model, checker = _setup(robot)
    settings = DatasetSettings(
        robot=robot,
        urdf_sha256=model.urdf_sha256,
        uniform=uniform,
        boundary=boundary,
        seed=seed,
        shard_size=shard_size,
        sampling=BoundarySettings(bisection_steps, jitter_per_pair, jitter_min, jitter_max),
    )
    console = Console()
    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    columns = (
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    with Progress(*columns, console=console) as progress:
        prepare(out, settings)
        todo = pending_shards(out, settings)
        total = uniform + boundary
        left = sum(sum(settings.shard_sizes(k)) for k in todo)
        task = progress.add_task(f"labelling ({workers} workers)", total=total, completed=total - left)
        n = generate(out, settings, workers, lambda k: progress.advance(task, k))
    resumed = f" (resumed: {total - left:,} were already there)" if left < total else ""
    console.print(f"wrote {n:,} configurations to {out}{resumed} in {time.perf_counter() - t0:.0f} s; "
                  f"{settings.n_shards} shards, URDF sha256 {model.urdf_sha256[:12]}…")


@app.command("train-cpn")
def train_cpn_cmd(
    ctx: typer.Context,
    data: Path = typer.Argument(..., help="A dataset folder from `teleprev collision dataset`."),
    out: Path = typer.Option(
        Path("models/cpn_leap_hand.safetensors"),
        "--out",
        "-o",
        help="Model file (a model card .md is written beside it).",
    ),
    robot: str = ROBOT,
    architecture: str = typer.Option(
        "grouped", help="grouped (one MLP per pair of fingers, noisy-OR per link) or plain (one MLP)."
    ),
    hidden: str = typer.Option("128,128,128", help="Hidden layer widths (of each group's MLP)."),
    activation: str = typer.Option("relu", help="relu (fastest at runtime), silu or tanh."),
    epochs: int = typer.Option(24, min=1),
    batch_size: int = typer.Option(1024, min=1),
    lr: float = typer.Option(2e-3, min=0.0, help="Peak learning rate (one-cycle schedule)."),
    pos_weight: float = typer.Option(
        2.0, min=0.0, help="Extra weight on colliding labels, times each link's negative/positive ratio."
    ),
    pair_weight: float = typer.Option(
        1.0, min=0.0, help="Grouped: weight of the auxiliary per-pair BCE (0: link labels only)."
    ),
    target_recall: float = typer.Option(
        0.998, min=0.0, max=1.0, help="Recall of colliding link labels the threshold must reach on validation."
    ),
    seed: int = typer.Option(0, min=0),
    device: str = DEVICE,
    heldout_uniform: int = typer.Option(
        50_000, min=0, help="Fresh uniform samples for the model card's figures (0: skip)."
    ),
    heldout_boundary: int = typer.Option(20_000, min=0, help="Fresh boundary samples for the model card's figures."),
) -> None:
    """Train the Self-Collision Prediction Network (per-link BCE, Adam) and pick its threshold for recall."""
    from rich.console import Console

    from teleprev.cli.values import check_finite, check_positive
    from teleprev.noncollision.mlp import ACTIVATIONS
    from teleprev.noncollision.train_cpn import CPNSettings, train_cpn

    check_training_paths(data, out)
    check_device(device)
    for option, value in (("--pos-weight", pos_weight), ("--pair-weight", pair_weight)):
        check_finite(option, value, "a finite number (0 or more)")
    check_positive("--lr", lr, "a finite learning rate more than 0")
    if activation not in ACTIVATIONS:
        raise typer.BadParameter(f"--activation must be one of {', '.join(ACTIVATIONS)}")
    if architecture not in ("grouped", "plain"):
        raise typer.BadParameter("--architecture must be grouped or plain")
    widths = _hidden(hidden)
    model, checker = _setup(robot)
    console = Console()
    settings = CPNSettings(
        architecture=architecture,
        hidden=widths,
        activation=activation,
        epochs=epochs,
        batch_size=batch_size,
        lr=lr,
        pos_weight=pos_weight,
        pair_weight=pair_weight,
        target_recall=target_recall,
        seed=seed,
        device=device,
    )

    def log(e) -> None:
        console.print(
            f"epoch {e.epoch:3d}/{epochs}  train {e.train_loss:.4f}  val {e.val_loss:.4f}  "
            f"worst-link AUC {e.val_auc_min_link:.4f}  recall@0.5 {e.val_recall_at_half:.4f}  {e.seconds:.1f} s"
        )

    result = train_cpn(data, model, checker, settings, log)
    _save_with_card(ctx, "cpn", out, result, model, checker, data, heldout_uniform, heldout_boundary, console)


@app.command("train-ccn")
def train_ccn_cmd(
    ctx: typer.Context,
    data: Path = typer.Argument(
        ..., help="A dataset folder from `teleprev collision dataset` (its colliding configurations are the inputs)."
    ),
    cpn: Path = typer.Option(Path("models/cpn_leap_hand.safetensors"), "--cpn", help="The trained CPN (kept frozen)."),
    out: Path = typer.Option(
        Path("models/ccn_leap_hand.safetensors"),
        "--out",
        "-o",
        help="Model file (a model card .md is written beside it).",
    ),
    robot: str = ROBOT,
    alpha: float = typer.Option(1.0, min=0.0, help="Weight of the MSE term (equation 8)."),
    beta: float = typer.Option(1.0, min=0.0, help="Weight of the collision-probability term (equation 8)."),
    grid: Path | None = typer.Option(None, "--grid", help="Take alpha and beta from a grid-search result (.json)."),
    hidden: str = typer.Option("256,256,256", help="Hidden layer widths."),
    epochs: int = typer.Option(12, min=1),
    batch_size: int = typer.Option(1024, min=1),
    lr: float = typer.Option(1e-3, min=0.0),
    val_exact: int = typer.Option(3000, min=10, help="Held-out invalid configurations checked exactly every epoch."),
    max_train: int = typer.Option(0, min=0, help="Use at most this many training configurations (0: all)."),
    seed: int = typer.Option(0, min=0),
    device: str = DEVICE,
    heldout_uniform: int = typer.Option(
        20_000, min=0, help="Fresh colliding uniform samples for the model card's figures."
    ),
    heldout_trajectory: int = typer.Option(
        5_000, min=0, help="Fresh colliding retargeted-trajectory frames for the card."
    ),
) -> None:
    """Train the Invalid Configuration Correction Network against the frozen CPN."""
    from rich.console import Console

    from teleprev.cli.outputs import check_input
    from teleprev.cli.values import check_finite, check_positive
    from teleprev.noncollision.train_ccn import CCNSettings, train_ccn

    check_training_paths(data, out)
    check_device(device)
    check_input(cpn, "--cpn", "CPN weights file")
    check_input(grid, "--grid", "grid-search result")
    for option, value in (("--alpha", alpha), ("--beta", beta)):
        check_finite(option, value, "a finite number (0 or more)")
    check_positive("--lr", lr, "a finite learning rate more than 0")
    widths = _hidden(hidden)
    if grid is not None:
        from teleprev.noncollision.grid_search import read_chosen

        alpha, beta = read_chosen(grid)
    model, checker = _setup(robot)
    console = Console()
    settings = CCNSettings(alpha=alpha, beta=beta, hidden=widths, epochs=epochs, batch_size=batch_size, lr=lr,
                           val_exact=val_exact, max_train=max_train, seed=seed, device=device)
    console.print(f"alpha = {alpha:g}, beta = {beta:g}")

    def log(e) -> None:
        console.print(
            f"epoch {e.epoch:3d}/{epochs}  loss {e.loss:.5f}  mse {e.mse:.5f}  p(collision) {e.collision:.4f}  "
            f"val valid (exact) {e.val_valid_frac:.4f}  deviation {e.val_mean_dev_rad:.4f} rad  {e.seconds:.1f} s"
        )

    result = train_ccn(data, cpn, model, checker, settings, log)
    grid_md = None
    if grid is not None and grid.with_suffix(".md").is_file():
        grid_md = grid.with_suffix(".md").read_text().split("\n\n", 1)[-1].strip()
    _save_with_card(
        ctx, "ccn", out, result, model, checker, data, heldout_uniform, heldout_trajectory, console, grid_md
    )


def _save_with_card(ctx, kind, out, result, model, checker, data, n_a, n_b, console, grid_md=None) -> None:
    from teleprev.noncollision import cards, evaluate
    from teleprev.noncollision.dataset import load_settings
    from teleprev.noncollision.mlp import CCN, CPN, save_model

    path = save_model(out, result.net)
    console.print(f"wrote {path} (best epoch {result.best_epoch}, {result.seconds / 60:.1f} min)")
    dataset_command = load_settings(data).command(data)
    if kind == "cpn":
        console.print(f"operating threshold {result.net.info.threshold:.4g}; validation: "
                      + ", ".join(f"{k} {v:.4f}" for k, v in result.val_figures.items() if isinstance(v, float)))
        if n_a == 0:
            return
        with console.status("held-out figures on fresh data"):
            figs = evaluate.cpn_heldout(model, checker, CPN(result.net), n_a, n_b)
        card = cards.cpn_card(path, result.net, figs, dataset_command, _command(ctx))
        shown = ("cpn_auc_min_link", "cpn_recall", "cpn_config_fnr", "cpn_boundary_auc_min_link")
    else:
        if n_a + n_b == 0:
            return
        with console.status("held-out figures on fresh data"):
            invalid = evaluate.invalid_set(model, checker, n_a, n_b)
            figs = evaluate.ccn_heldout(checker, CCN(result.net, model.lower, model.upper), invalid)
        card = cards.ccn_card(path, result.net, figs, grid_md, dataset_command, _command(ctx))
        shown = ("ccn_valid_frac", "ccn_mean_dev_rad", "ccn_valid_frac_uniform", "ccn_valid_frac_trajectory")
    console.print("held-out: " + ", ".join(f"{k} {figs[k]:.4f}" for k in shown if k in figs))
    console.print(f"wrote {card}")


@app.command("grid-search")
def grid_search_cmd(
    data: Path = typer.Argument(..., help="A dataset folder from `teleprev collision dataset`."),
    cpn: Path = typer.Option(Path("models/cpn_leap_hand.safetensors"), "--cpn", help="The trained CPN (kept frozen)."),
    out: Path = typer.Option(Path("runs/ccn_grid"), "--out", "-o", help="Writes <out>.json and <out>.md."),
    robot: str = ROBOT,
    alphas: str = typer.Option("1,10", help="Comma-separated alpha values."),
    betas: str = typer.Option("0.03,0.1,0.3,1,3", help="Comma-separated beta values."),
    min_valid: float = typer.Option(
        0.95, min=0.0, max=1.0,
        help="Validity the chosen pair must reach. The shipped CCN used 0.99: the Corrector's 1 ms p99 leaves room "
             "for its fallback on fewer than 1 % of inputs, and it takes only as much of the correction as it needs.",
    ),
    hidden: str = typer.Option("256,256,256", help="Hidden layer widths."),
    epochs: int = typer.Option(4, min=1, help="Epochs per grid point."),
    max_train: int = typer.Option(200_000, min=0, help="Training configurations per grid point (0: all)."),
    val_exact: int = typer.Option(2000, min=10),
    seed: int = typer.Option(0, min=0),
    device: str = DEVICE,
) -> None:
    """Train a short CCN per (alpha, beta), score validity and deviation exactly, and pick the pair."""
    from rich.console import Console
    from rich.table import Table

    from teleprev.cli.outputs import check_input, check_output
    from teleprev.noncollision.grid_search import grid_search, write_grid
    from teleprev.noncollision.train_ccn import CCNSettings

    for written in (out.with_suffix(".json"), out.with_suffix(".md")):
        check_output(written, "--out", make_parents=True)
    check_input(data, "DATA", "collision dataset folder", folder=True)
    check_input(cpn, "--cpn", "CPN weights file")
    check_device(device)
    a, b = _floats(alphas, "--alphas"), _floats(betas, "--betas")
    widths = _hidden(hidden)
    model, checker = _setup(robot)
    console = Console()
    settings = CCNSettings(
        hidden=widths, epochs=epochs, max_train=max_train, val_exact=val_exact, seed=seed, device=device
    )

    def log(p) -> None:
        console.print(
            f"alpha {p.alpha:<6g} beta {p.beta:<6g}  valid {p.valid_frac:.4f}  deviation {p.mean_dev_rad:.4f} rad  "
            f"({p.seconds:.0f} s)"
        )

    result = grid_search(data, cpn, model, checker, a, b, settings, min_valid, log)
    js, md = write_grid(result, out)
    table = Table(title="CCN loss weights", title_justify="left")
    for col in ("alpha", "beta", "valid (exact)", "mean deviation (rad)", ""):
        table.add_column(col, justify="right")
    for p in result.points:
        table.add_row(
            f"{p.alpha:g}",
            f"{p.beta:g}",
            f"{p.valid_frac:.4f}",
            f"{p.mean_dev_rad:.4f}",
            "chosen" if p == result.chosen else "",
        )
    console.print(table)
    console.print(f"chosen alpha = {result.chosen.alpha:g}, beta = {result.chosen.beta:g}; wrote {js} and {md}")
