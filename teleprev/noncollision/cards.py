"""Model cards: the markdown written next to each trained model, with the numbers of the run that made it."""

from __future__ import annotations

import datetime as _dt
import platform
from pathlib import Path

from teleprev.noncollision.mlp import MLP


def _arch(net: MLP) -> str:
    i = net.info
    params = sum(w.size + b.size for w, b in zip(net.w, net.b))
    sizes = " -> ".join(map(str, [i.width_in, *i.hidden, i.width_out]))
    tail = f"{i.activation} between layers, {params:,} parameters (float32)"
    if len(i.groups) == 1:
        return f"MLP {sizes}, {tail}"
    groups = "; ".join(f"joints [{', '.join(g.inputs)}] -> {len(g.outputs)} pairs" for g in i.groups)
    return (f"{len(i.groups)} parallel MLPs {sizes} (one per group of joints that can collide with each other, inputs "
            f"zero-padded, outputs one slot per checked link pair), each link's probability the noisy-OR of its pairs' "
            f"sigmoids; {tail}. Groups: {groups}")


def _dataset(d: dict) -> str:
    s = d.get("sampling", {})
    return (
        f"`{d.get('path')}`: {d.get('samples', 0):,} configurations of `{d.get('robot')}` "
        f"(URDF sha256 `{d.get('urdf_sha256', '')[:16]}…`), {d.get('uniform', 0):,} uniform in the joint limits and "
        f"{d.get('boundary', 0):,} near the collision boundary (bisection of free/colliding pairs, {s.get('steps')} steps, "
        f"{s.get('jitter_per_pair')} jittered copies per boundary point with sigma log-uniform in "
        f"[{s.get('jitter_min')}, {s.get('jitter_max')}] rad), seed {d.get('seed')}; labels from the exact fcl checker."
    )


def _table(rows: list[tuple[str, str, str]]) -> str:
    out = ["| figure | value | target |", "|---|---:|---|"]
    out += [f"| {k} | {v} | {t} |" for k, v, t in rows]
    return "\n".join(out)


def _fmt(v) -> str:
    return f"{v:.4f}" if isinstance(v, float) else str(v)


def _footer(command: str, seconds: float, device: str) -> str:
    return (
        f"## Reproduce\n\n```\n{command}\n```\n\n"
        f"Trained in {seconds / 60:.1f} min on {device} ({platform.processor() or platform.machine()}), "
        f"{_dt.date.today().isoformat()}.\n"
    )


def cpn_card(path: Path, net: MLP, heldout: dict, dataset_command: str, command: str) -> Path:
    t = net.info.training or {}
    s = t.get("settings", {})
    hist = t.get("history", [])
    per_link = heldout.get("cpn_auc_per_link", {})
    rows = [
        ("cpn_auc_min_link (uniform held-out)", _fmt(heldout["cpn_auc_min_link"]), ">= 0.995"),
        ("cpn_recall", _fmt(heldout["cpn_recall"]), ">= 0.995"),
        ("cpn_config_fnr", _fmt(heldout["cpn_config_fnr"]), "<= 0.005"),
        ("cpn_precision", _fmt(heldout["cpn_precision"]), ""),
        ("cpn_config_fpr (free configurations flagged)", _fmt(heldout["cpn_config_fpr"]), ""),
    ]
    for key in ("auc_min_link", "recall", "config_fnr"):
        if f"cpn_boundary_{key}" in heldout:
            rows.append(
                (
                    f"cpn_boundary_{key} (boundary held-out)",
                    _fmt(heldout[f"cpn_boundary_{key}"]),
                    "(harder: all within ~0.1 rad of contact)",
                )
            )
    text = f"""# CPN: LEAP Hand self-collision prediction network

`{path.with_suffix(".safetensors").name}`: joint configuration (16 joints, radians) -> per-link collision probability
for the {len(net.info.link_names)} links with collision geometry ({", ".join(net.info.link_names)}).
Appendix A.1 of TelePreview (arXiv 2412.13548). Loaded by `teleprev.noncollision.mlp.load_model` (numpy, no torch).

## Data

{_dataset(t.get("dataset", {}))}
Split: {t.get("dataset", {}).get("train", 0):,} training / {t.get("dataset", {}).get("val", 0):,} validation.
Made with:

```
{dataset_command}
```

## Architecture

{_arch(net)}. Input features: (q - middle of limits) / half range.

## Training

Mean per-link binary cross-entropy (equation 5), each link's positive term weighted by
{s.get("pos_weight")} x its negative/positive ratio (missed collisions cost more than false alarms){_pair_loss(net, s)}; Adam,
one-cycle learning rate peaking at {s.get("lr")}, batch {s.get("batch_size")}, {s.get("epochs")} epochs, seed {s.get("seed")};
weights of the epoch with the best validation loss (epoch {t.get("best_epoch")}).
Operating threshold {net.info.threshold:.4g}: the largest at which the validation set reaches recall >= {s.get("target_recall")}
of colliding link labels and <= {s.get("target_config_fnr")} colliding configurations predicted entirely free.

Validation per epoch (loss, worst-link AUC, recall at 0.5):

{_history_table(hist, ("val_loss", "val_auc_min_link", "val_recall_at_half"))}

## Held-out figures

Fresh data generated after training ({heldout.get("cpn_heldout_uniform", 0):,} uniform, {heldout.get("cpn_heldout_boundary", 0):,} boundary samples, seed {heldout.get("cpn_heldout_seed", "")}),
labelled by the exact checker, at the operating threshold:

{_table(rows)}

Per-link ROC AUC (uniform held-out): {", ".join(f"{k} {v:.4f}" for k, v in per_link.items())}.

{_footer(command, t.get("seconds", 0.0), t.get("device", "cpu"))}"""
    out = path.with_suffix(".md")
    out.write_text(text)
    return out


def _pair_loss(net: MLP, s: dict) -> str:
    if net.info.combine != "noisy_or" or not s.get("pair_weight"):
        return ""
    return (
        f", plus {s['pair_weight']} x the mean per-pair BCE of the output slots against the dataset's per-pair labels "
        "(each slot is one checked link pair; positives weighted the same way)"
    )


def _history_table(hist: list[dict], keys: tuple[str, ...]) -> str:
    if not hist:
        return "(no history)"
    out = ["| epoch | " + " | ".join(keys) + " |", "|---:|" + "---:|" * len(keys)]
    for h in hist:
        out.append(f"| {h['epoch']} | " + " | ".join(f"{h[k]:.4f}" for k in keys) + " |")
    return "\n".join(out)


def ccn_card(path: Path, net: MLP, heldout: dict, grid_md: str | None, dataset_command: str, command: str) -> Path:
    t = net.info.training or {}
    s = t.get("settings", {})
    rows = [
        ("ccn_valid_frac (CCN alone, exact check)", _fmt(heldout["ccn_valid_frac"]), ">= 0.95"),
        ("ccn_mean_dev_rad (mean absolute joint deviation)", _fmt(heldout["ccn_mean_dev_rad"]), "(lower is better)"),
    ]
    for src in ("uniform", "trajectory"):
        if f"ccn_valid_frac_{src}" in heldout:
            rows.append((f"ccn_valid_frac_{src}", _fmt(heldout[f"ccn_valid_frac_{src}"]), ""))
            rows.append((f"ccn_mean_dev_rad_{src}", _fmt(heldout[f"ccn_mean_dev_rad_{src}"]), ""))
    grid = f"\n## Loss weights (grid search)\n\n{grid_md}\n" if grid_md else ""
    text = f"""# CCN: LEAP Hand invalid configuration correction network

`{path.with_suffix(".safetensors").name}`: a self-colliding configuration (16 joints, radians) -> a corrected one nearby,
q_hat = clip(q + half_range * net(q), lower, upper). Appendix A.2 of TelePreview (arXiv 2412.13548).
Used by `teleprev.noncollision.corrector.Corrector`, which checks every proposal with the exact checker and falls
back when it still collides. Trained against the CPN `{t.get("cpn", {}).get("file")}` (sha256 `{t.get("cpn", {}).get("sha256", "")[:16]}…`).

## Data

The {t.get("dataset", {}).get("invalid", 0):,} colliding configurations of {_dataset(t.get("dataset", {}))}
Split: {t.get("dataset", {}).get("train", 0):,} training / {t.get("dataset", {}).get("val", 0):,} validation
({s.get("val_exact")} of them checked exactly every epoch). Made with:

```
{dataset_command}
```

## Architecture

{_arch(net)}; the last layer starts at zero (the identity).

## Training

L = alpha * MSE(q_hat, q) + beta * mean link probability of the frozen CPN at q_hat (equations 6-8),
alpha = {s.get("alpha")}, beta = {s.get("beta")}; Adam, one-cycle learning rate peaking at {s.get("lr")}, batch {s.get("batch_size")},
{s.get("epochs")} epochs, seed {s.get("seed")}. Convergence monitored by the exact collision rate of the outputs on the
validation set; the epoch with the highest validity is kept (epoch {t.get("best_epoch")}).

{_history_table(t.get("history", []), ("loss", "mse", "collision", "val_valid_frac", "val_mean_dev_rad"))}
{grid}
## Held-out figures

Fresh invalid configurations generated after training: {heldout.get("ccn_n_invalid", 0):,} in all, colliding uniform samples
and colliding frames of retargeted human hand trajectories (open, fist, pinch, spread, crossed fingers), checked with the
exact checker:

{_table(rows)}

{_footer(command, t.get("seconds", 0.0), t.get("device", "cpu"))}"""
    out = path.with_suffix(".md")
    out.write_text(text)
    return out
