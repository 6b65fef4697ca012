"""`teleprev robot`: inspect a robot description and its self-collision statistics."""

from __future__ import annotations

from pathlib import Path

import typer

app = typer.Typer(help="Inspect robot descriptions (URDF): joints, limits, self-collision.", no_args_is_help=True)

URDF_ARG = typer.Argument(..., help="A URDF file, or the name of one in urdf/ (e.g. leap_hand_right).")


@app.command("info")
def info(urdf: str = URDF_ARG) -> None:
    """Print the joint table (name, limits, speed) and whether the neutral pose is collision-free."""
    from rich.console import Console
    from rich.table import Table

    from teleprev.robot.model import load_robot

    model = load_robot(urdf)
    console = Console()
    table = Table(title=f"{model.name}  ({model.urdf_path})", title_justify="left")
    for col, just in (
        ("joint", "left"),
        ("type", "left"),
        ("lower", "right"),
        ("upper", "right"),
        ("speed", "right"),
        ("mimics", "left"),
    ):
        table.add_column(col, justify=just)
    for j in model.desc.joints:
        if j.type == "fixed":
            continue
        unit = "m" if j.type == "prismatic" else "rad"
        table.add_row(
            j.name, j.type, f"{j.lower:.4f} {unit}", f"{j.upper:.4f} {unit}", f"{j.velocity:g} {unit}/s",
            f"{j.mimic.joint} x{j.mimic.multiplier:g}" if j.mimic else "",
        )
    console.print(table)
    console.print(f"{len(model.joint_names)} actuated joints, {len(model.link_names)} links, "
                  f"{sum(len(link.collisions) for link in model.links.values())} collision shapes")
    if not any(link.collisions for link in model.links.values()):
        return
    from teleprev.robot.exclusions import exclusions_path

    if not exclusions_path(model.urdf_path).exists():
        console.print(f"[yellow]no self-collision exclusion list yet[/]: `teleprev robot exclusions {urdf}` writes one")
        return
    from teleprev.robot.collision import SelfCollisionChecker

    report = SelfCollisionChecker(model).check(model.neutral())
    if report.colliding:
        console.print(
            f"neutral pose: [bold red]in self-collision[/] ({', '.join(f'{a}-{b}' for a, b in report.pairs)})"
        )
    else:
        console.print("neutral pose: [bold green]collision-free[/]")


@app.command("check")
def check(
    urdf: str = URDF_ARG,
    samples: int = typer.Option(10_000, "--samples", "-n", min=1, help="Uniform samples within the joint limits."),
    seed: int = typer.Option(0, min=0, help="Random seed."),
) -> None:
    """Print the self-collision rate of uniform samples, overall and per link."""
    import numpy as np
    from rich.console import Console
    from rich.progress import Progress
    from rich.table import Table

    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    model = load_robot(urdf)
    checker = SelfCollisionChecker(model)
    rng = np.random.default_rng(seed)
    pairs = np.zeros(len(checker.link_pairs))
    per_link = np.zeros(len(checker.link_names))
    any_hit = 0
    with Progress(transient=True) as progress:
        task = progress.add_task("sampling", total=samples)
        done = 0
        while done < samples:
            n = min(2000, samples - done)
            m = checker.pair_matrix(model.sample_uniform(n, rng))
            pairs += m.sum(0)
            per_link += checker.labels_from_pairs(m).sum(0)
            any_hit += int(m.any(1).sum())
            done += n
            progress.advance(task, n)
    console = Console()
    console.print(
        f"[bold]{model.name}[/]: {any_hit / samples:.1%} of {samples} uniform configurations are in self-collision"
    )
    table = Table(title="per link", title_justify="left")
    table.add_column("link")
    table.add_column("in collision", justify="right")
    for name, count in zip(checker.link_names, per_link):
        table.add_row(name, f"{count / samples:.1%}")
    console.print(table)
    top = np.argsort(-pairs)[:8]
    console.print("most frequent pairs: " + ", ".join(
        f"{checker.link_pairs[i][0]}-{checker.link_pairs[i][1]} {pairs[i] / samples:.1%}" for i in top if pairs[i] > 0
    ))


@app.command("exclusions")
def exclusions(
    urdf: str = URDF_ARG,
    samples: int = typer.Option(
        20_000, "--samples", "-n", min=0, help="Uniform samples used to find pairs that always touch."
    ),
    seed: int = typer.Option(0, min=0, help="Random seed."),
) -> None:
    """Write the list of link pairs the self-collision check leaves out, next to the URDF."""
    from rich.console import Console
    from rich.progress import Progress

    from teleprev.robot.exclusion_search import compute_exclusions
    from teleprev.robot.exclusions import write_exclusions
    from teleprev.robot.model import load_robot

    model = load_robot(urdf)
    with Progress(transient=True) as progress:
        task = progress.add_task("sampling", total=samples)
        excl = compute_exclusions(model, samples, seed, progress=lambda n: progress.advance(task, n))
    path = write_exclusions(model, excl)
    always = [p for p in excl.pairs if p.reason == "always"]
    Console().print(
        f"wrote {Path(path)}: {len(excl.pairs) - len(always)} adjacent pairs, {len(always)} always in contact"
    )
