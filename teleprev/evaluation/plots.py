"""One PNG per episode: recorded vs re-run hand joints, with the steps the Corrector changed marked."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev.evaluation.reproduce import Rerun
from teleprev import topics


def plot_episodes(r: Rerun, out_dir: str | Path, max_joints: int = 8) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    spans = [(e.index, e.task, e.start_ns, e.stop_ns) for e in r.episodes] or [(0, "session", int(r.t_ns[0]), None)]
    stream, names = (topics.CORRECTED, r.effector_names)
    for index, task, start, stop in spans:
        rows = (r.t_ns >= start) & (r.t_ns < (stop if stop is not None else np.iinfo(np.int64).max))
        if not rows.any():
            continue
        t = (r.t_ns[rows] - start) / 1e9
        recorded, rerun = r.recorded[stream][rows], r.rerun[stream][rows]
        changed = np.isin(r.corrector[rows], ("ccn", "fallback"))
        joints = list(range(min(len(names), max_joints)))
        fig, axes = plt.subplots(len(joints), 1, figsize=(10, 1.4 * len(joints) + 0.8), sharex=True, squeeze=False)
        for ax, j in zip(axes[:, 0], joints):
            ax.plot(t, recorded[:, j], color="0.6", lw=2.5, label="recorded")
            ax.plot(t, rerun[:, j], color="tab:blue", lw=1.0, label="re-run")
            for x in t[changed]:
                ax.axvline(x, color="tab:red", alpha=0.08, lw=1)
            ax.set_ylabel(names[j], rotation=0, labelpad=18)
        axes[0, 0].legend(loc="upper right", fontsize=8)
        axes[0, 0].set_title(f"{r.session.name}: episode {index} ({task}) - {stream}; red: steps the Corrector changed")
        axes[-1, 0].set_xlabel("seconds into the episode")
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
    panels = (("collision_before_frac", "steps the Corrector changed"), ("deviation_max_rad", "largest correction (rad)"),
              ("latency_ms_p99", "step p99 (ms)"), ("realtime_x", "re-run speed (x real time)"))
    fig, axes = plt.subplots(1, len(panels), figsize=(3.2 * len(panels) + 2, 0.28 * len(sessions) + 1.6), sharey=True, squeeze=False)
    y = np.arange(len(sessions))
    for ax, (key, label) in zip(axes[0], panels):
        values = [float(s["overall"].get(key, 0.0)) for s in sessions]
        colors = ["tab:red" if s.get("regressions") or not s.get("bit_identical", True) else "tab:blue" for s in sessions]
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
