"""One PNG per episode (what the re-run commanded, arm and end effector, with units; the retargeted target
against the corrected one; the steps the Corrector changed shaded; how far the re-run is from the recording),
and corpus.png for many sessions."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.evaluation.reproduce import Rerun

GROUP = 4  # end-effector joints per panel (a LEAP Hand finger)


def effector_unit(effector_name: str) -> str:
    return {"parallel_gripper": "m (jaw opening)", "vacuum": "on (1) / off (0)"}.get(effector_name, "rad")


def changed_spans(t: np.ndarray, changed: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) times of each run of consecutive changed steps (a run of one step spans to the next)."""
    if not changed.any():
        return []
    edges = np.diff(np.r_[0, changed.astype(np.int8), 0])
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    nxt = np.r_[t[1:], t[-1]]
    return [(float(t[a]), float(nxt[b - 1])) for a, b in zip(starts, ends)]


def plot_episodes(r: Rerun, out_dir: str | Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    spans = [(e.index, e.task, e.start_ns, e.stop_ns) for e in r.episodes] or [(0, "session", int(r.t_ns[0]), None)]
    eff_names = r.effector_names
    groups = [list(range(k, min(k + GROUP, len(eff_names)))) for k in range(0, len(eff_names), GROUP)]
    unit = effector_unit(r.effector.name)
    for index, task, start, stop in spans:
        end = stop if stop is not None else np.iinfo(np.int64).max
        rows = (r.t_ns >= start) & (r.t_ns < end)
        if not rows.any():
            continue
        t = (r.t_ns[rows] - start) / 1e9
        arm = r.commands[topics.COMMAND_ARM].select(start, end)  # on the commands' own stamps
        t_arm = (arm.t_ns - start) / 1e9
        shaded = changed_spans(t, np.isin(r.corrector[rows], ("ccn", "fallback")))
        fig, axes = plt.subplots(2 + len(groups), 1, figsize=(11, 2.1 * (2 + len(groups)) + 0.6), sharex=True,
                                 squeeze=False, height_ratios=[3] + [3] * len(groups) + [1.4])
        axes = axes[:, 0]
        arm_ax, diff_ax = axes[0], axes[-1]
        for j, name in enumerate(r.arm_names):
            arm_ax.plot(t_arm, arm.recorded[:, j], color="0.82", lw=3)
            arm_ax.plot(t_arm, arm.rerun[:, j], lw=1.1, label=name)
        arm_ax.set_ylabel("arm command\n(rad)")
        arm_ax.legend(loc="upper right", fontsize=7, ncol=len(r.arm_names))
        for ax, group in zip(axes[1:-1], groups):
            for j in group:
                line, = ax.plot(t, r.rerun[topics.CORRECTED][rows][:, j], lw=1.1, label=eff_names[j])
                ax.plot(t, r.rerun[topics.RETARGETED][rows][:, j], lw=0.9, ls="--", color=line.get_color())
            ax.set_ylabel(f"end effector\n({unit})")
            ax.legend(loc="upper right", fontsize=7, ncol=len(group), title_fontsize=7,
                      title="solid: corrected, dashed: retargeted")
        corrected = (r.rerun[topics.CORRECTED][rows], r.recorded[topics.CORRECTED][rows])
        for times, (a, b), label in ((t_arm, (arm.rerun, arm.recorded), "arm command"), (t, corrected, "corrected")):
            gap = np.abs(a - b)
            worst = np.where(np.isnan(gap).all(axis=1), np.nan, np.nanmax(np.nan_to_num(gap, nan=0.0), axis=1))
            diff_ax.plot(times, worst, lw=1.0, label=label)
        same = arm.same() and np.array_equal(*corrected, equal_nan=True)
        diff_ax.set_ylabel("|re-run −\nrecorded|")
        diff_ax.legend(loc="upper right", fontsize=7, ncol=2,
                       title="re-run = recording, bit for bit" if same else "re-run differs from the recording",
                       title_fontsize=7)
        for ax in axes:
            for a, b in shaded:
                ax.axvspan(a, b, color="tab:red", alpha=0.12, lw=0)
        axes[0].set_title(f"{r.session.name}: episode {index} ({task}); shaded: steps the Corrector changed "
                          f"({len(shaded)} spans)", fontsize=10)
        axes[-1].set_xlabel("seconds into the episode")
        fig.tight_layout()
        path = out_dir / f"{r.session.stem}_episode{index}.png"
        fig.savefig(path, dpi=80)
        plt.close(fig)
        paths.append(path)
    return paths


def plot_corpus(report: dict, out_dir: str | Path, max_sessions: int = 40) -> Path:
    """corpus.png: a row per session, worst first (as the report orders them), one panel per figure
    that tells sessions apart; failed sessions are named in the title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sessions = report["sessions"][:max_sessions]
    names = [Path(s["session"]).name for s in sessions]
    panels = (
        ("collision_before_frac", "steps the Corrector changed"),
        ("deviation_max_rad", "largest correction (rad)"),
        ("latency_ms_p99", "step p99 (ms)"),
        ("realtime_x", "re-run speed (x real time)"),
    )
    fig, axes = plt.subplots(
        1, len(panels), figsize=(3.2 * len(panels) + 2, 0.28 * len(sessions) + 1.6), sharey=True, squeeze=False
    )
    y = np.arange(len(sessions))
    for ax, (key, label) in zip(axes[0], panels):
        values = [float(s["overall"].get(key, 0.0)) for s in sessions]
        colors = [
            "tab:red" if s.get("regressions") or not s.get("bit_identical", True) else "tab:blue" for s in sessions
        ]
        ax.barh(y, values, color=colors)
        ax.set_title(label, fontsize=9)
        ax.tick_params(labelsize=7)
    axes[0, 0].set_yticks(y, names)
    axes[0, 0].invert_yaxis()  # worst at the top
    total = len(report["sessions"]) + len(report.get("failed", []))
    failed = [Path(f["session"]).name for f in report.get("failed", [])]
    title = f"{len(sessions)} of {total} sessions, worst first (red: regressed or not reproduced)"
    if failed:
        title += f"; failed: {', '.join(failed[:5])}" + (" ..." if len(failed) > 5 else "")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = out_dir / "corpus.png"
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
