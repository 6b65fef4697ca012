"""The study's tables (screen and CSV) and plots in the style of the paper's figures 9 and 10."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from teleprev.study.questionnaire import QUESTIONS
from teleprev.study.stats import Group, TableIIIRow

EE_NAMES = {"leap_hand": "LeapHand (16-DoF)", "parallel_gripper": "Parallel-jaw Gripper (1-DoF)", "vacuum": "Vacuum Gripper (binary)"}


def _pct(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.0%}"


def print_tables(console: Console, groups: list[Group], rows: list[TableIIIRow]) -> None:
    """A row per measure, a column per (condition, end effector); then Table III."""
    t = Table(title="per condition and end effector (execution time: successful, kept episodes)", title_justify="left")
    t.add_column("measure", no_wrap=True)
    for g in groups:
        t.add_column(f"{g.condition or '(none)'}\n{g.end_effector}", justify="right")
    t.add_row("sessions", *(str(g.sessions) for g in groups))
    t.add_row("execution time (s)", *(f"{g.execution_time_s.text()} (n={g.execution_time_s.n})" for g in groups))
    t.add_row("success rate", *(f"{_pct(g.success_rate)} of {g.episodes_with_outcome}" for g in groups))
    t.add_row("practice time (s)", *(f"{g.practice_time_s.text()} (n={g.practice_time_s.n})" for g in groups))
    for q in QUESTIONS:
        label = q.label + (" (higher is better)" if q.higher_is_better else "")
        t.add_row(label, *(g.likert[q.key].text(2) if g.surveys else "no survey" for g in groups))
    console.print(t)
    t3 = Table(title="Table III: average execution time (s), w/o vs w/ preview", title_justify="left")
    for col in ("End-Effector", "w/o Preview", "w/ Preview", "Improvement"):
        t3.add_column(col, justify="left" if col == "End-Effector" else "right")
    for r in rows:
        t3.add_row(EE_NAMES.get(r.end_effector, r.end_effector), r.without.text(), r.with_.text(),
                   "n/a" if r.improvement_s is None else f"{r.improvement_s:+.1f}")
    console.print(t3)


def write_csv(out: Path, groups: list[Group], rows: list[TableIIIRow]) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    per_group = out / "study.csv"
    with per_group.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["condition", "end_effector", "sessions", "execution_time_mean_s", "execution_time_std_s", "execution_time_n",
                    "success_rate", "episodes_with_outcome", "practice_time_mean_s", "practice_time_std_s", "practice_n", "surveys",
                    *(f"{q.key}_{s}" for q in QUESTIONS for s in ("mean", "std"))])
        for g in groups:
            blank = lambda v: "" if v is None else v  # noqa: E731 (missing stays empty, never 0)
            w.writerow([g.condition, g.end_effector, g.sessions, blank(g.execution_time_s.mean), blank(g.execution_time_s.std),
                        g.execution_time_s.n, blank(g.success_rate), g.episodes_with_outcome, blank(g.practice_time_s.mean),
                        blank(g.practice_time_s.std), g.practice_time_s.n, g.surveys,
                        *(blank(getattr(g.likert[q.key], s)) for q in QUESTIONS for s in ("mean", "std"))])
    table3 = out / "table_iii.csv"
    with table3.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["end_effector", "without_mean_s", "without_std_s", "with_mean_s", "with_std_s", "improvement_s"])
        for r in rows:
            w.writerow([r.end_effector, r.without.mean, r.without.std, r.with_.mean, r.with_.std, r.improvement_s])
    return [per_group, table3]


def plot_likert(out: Path, groups: list[Group]) -> Path | None:
    """Figure 9: a bar per condition for each Likert dimension, with std error bars."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rated = [g for g in groups if g.surveys]
    if not rated:
        return None
    fig, ax = plt.subplots(figsize=(9, 4))
    width = 0.8 / len(rated)
    x = np.arange(len(QUESTIONS))
    for i, g in enumerate(rated):
        means = [g.likert[q.key].mean for q in QUESTIONS]
        stds = [g.likert[q.key].std for q in QUESTIONS]
        ax.bar(x + (i - (len(rated) - 1) / 2) * width, means, width, yerr=stds, capsize=3,
               label=f"{g.condition or '(none)'} - {g.end_effector} (n={g.surveys})")
    ax.set_xticks(x, [q.label + ("\n(higher is better)" if q.higher_is_better else "") for q in QUESTIONS])
    ax.set_ylim(0, 5.5)
    ax.set_ylabel("rating (1-5)")
    ax.set_title("Subjective workload and performance by condition")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = out / "likert.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_practice(out: Path, groups: list[Group], practice: dict[str, list[float]]) -> Path | None:
    """Figure 10: practice time per condition, mean bar with every participant's time as a point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    conditions = [c for c, v in practice.items() if v]
    if not conditions:
        return None
    fig, ax = plt.subplots(figsize=(6, 4))
    for i, c in enumerate(conditions):
        v = np.asarray(practice[c])
        ax.bar(i, v.mean(), 0.6, yerr=v.std(ddof=1) if len(v) > 1 else 0, capsize=4, alpha=0.6)
        ax.scatter(np.full(len(v), i) + np.linspace(-0.15, 0.15, len(v)), v, color="k", s=12, zorder=3)
    ax.set_xticks(range(len(conditions)), [c or "(none)" for c in conditions])
    ax.set_ylabel("practice time until ready (s)")
    ax.set_title("Practice time per condition")
    fig.tight_layout()
    path = out / "practice_time.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
