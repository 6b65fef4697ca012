"""Plots in the style of the paper's figure 9 (Likert ratings) and figure 10 (practice time)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from teleprev.study.facts import SessionFacts
from teleprev.study.questionnaire import QUESTIONS
from teleprev.study.stats import Group
from teleprev.study.tables import BETTER, group_labels


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _err(std: float | None) -> float:
    return np.nan if std is None else std  # nan: no error bar, rather than a bar of zero spread


def plot_likert(out: Path, groups: list[Group]) -> Path | None:
    """Figure 9: for each Likert dimension a bar per group (mean, std error bar). None when nobody answered."""
    surveyed = [g for g in groups if g.surveys]
    rated = list(zip(surveyed, group_labels(surveyed)))  # labelled by what varies among the plotted groups
    if not rated:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 4.5))
    width = 0.8 / len(rated)
    x = np.arange(len(QUESTIONS))
    for i, (g, label) in enumerate(rated):
        means = [g.likert[q.key].mean for q in QUESTIONS]
        errs = [_err(g.likert[q.key].std) for q in QUESTIONS]
        ax.bar(
            x + (i - (len(rated) - 1) / 2) * width, means, width, yerr=errs, capsize=3, label=f"{label} (n={g.surveys})"
        )
    ax.set_xticks(x, [q.label + (f"\n({BETTER})" if q.higher_is_better else "") for q in QUESTIONS])
    ax.set_ylim(0, 5.5)
    ax.set_yticks(range(1, 6))
    ax.set_ylabel("rating, 1-5 (higher = more, mean ± std)")
    ax.set_title("Subjective workload and performance by condition")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "likert.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_practice(out: Path, groups: list[Group], sessions: list[SessionFacts]) -> Path | None:
    """Figure 10: practice time until ready per group: mean bar, std error bar, one point per practice session."""
    def times(g: Group) -> list[float]:
        return [s.practice_time_s for s in sessions if s.practice and s.practice_time_s is not None
                and (s.condition, s.end_effector) == (g.condition, g.end_effector)]

    practiced = [g for g in groups if times(g)]
    series = [(f"{label}\n(n={g.practice_time_s.n})", np.asarray(times(g)), g.practice_time_s.std)
              for g, label in zip(practiced, group_labels(practiced, "\n"))]
    if not series:
        return None
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(max(5, 1.6 * len(series)), 4))
    for i, (_, v, std) in enumerate(series):
        ax.bar(i, v.mean(), 0.6, yerr=_err(std), capsize=4, alpha=0.6)
        ax.scatter(i + np.linspace(-0.15, 0.15, len(v)), v, color="k", s=12, zorder=3)
    ax.set_xticks(range(len(series)), [s[0] for s in series])
    ax.set_ylabel("practice time until ready (s)")
    ax.set_title("Practice time per condition")
    ax.set_xlabel("bar: mean ± std; point: one practice session", fontsize=8)
    fig.tight_layout()
    path = out / "practice_time.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
