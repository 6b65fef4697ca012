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
