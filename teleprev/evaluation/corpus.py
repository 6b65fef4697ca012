"""`teleprev eval` over a corpus: every session re-run as a task of its own (in this process, in local
worker processes, or on a Ray cluster: teleprev.corpus.executor), then one regression report.

The report is evaluate()'s JSON for the sessions that ran, plus:

    sessions[*].rank           1 = worst; the list is ordered worst first (see `badness`)
    sessions[*].regressions    this session against the same session in the baseline, when it has it
    sessions[*].physics        with --physics: each episode's outcome as recorded, with the recorded and with
                               the re-computed commands, and the episodes that regressed (evaluation/physics.py)
    failed                     sessions that could not be evaluated, and why (their worker died twice,
                               the file is not a session, ...): they never stop the others
    corpus                     how it ran: sessions, failed, executor, workers, wall time

A session's plots (recorded vs re-run joints per episode) are drawn by the task that re-ran it, so only
the small metrics dict travels back; the corpus figure (plots.plot_corpus) is drawn once at the end.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from teleprev.corpus.executor import Outcome, run_task
from teleprev.evaluation.report import Regression, Tolerances, compare, default_tolerances, make_report

PRELOAD = ["numpy", "teleprev.evaluation.evaluate", "teleprev.evaluation.plots", "teleprev.evaluation.preload"]


@dataclass(frozen=True)
class EvalJob:
    models: str | None = None
    rig: str | None = None
    plots: str | None = None  # folder for the per-episode PNGs (absolute: a worker's working folder differs)
    physics: bool = False  # each session played into the physics world too (teleprev/evaluation/physics.py)


def eval_one(job: EvalJob, path: str, emit) -> dict:
    """A task: one session re-run and measured; its entry of the report (and its plots, when asked)."""
    from teleprev.evaluation.evaluate import evaluate

    result = evaluate([path], job.models, job.rig, physics=job.physics)
    entry = result.report["sessions"][0]
    if job.plots:
        from teleprev.evaluation.plots import plot_episodes

        entry["plots"] = [str(p) for p in plot_episodes(result.reruns[0], job.plots)]
    return entry


@dataclass
class CorpusEvaluation:
    report: dict
    regressions: list[Regression] | None = None  # of the overall figures, against the baseline's
    failed: dict[str, str] = field(default_factory=dict)
    plots: list[Path] = field(default_factory=list)

    @property
    def outcome_regressions(self) -> list[str]:
        """With physics: the episodes the re-computed commands turn from success to failure."""
        from teleprev.evaluation.evaluate import outcome_regressions

        return outcome_regressions(self.report)


def badness(entry: dict) -> tuple:
    """Sort key, larger is worse: regressions (against the baseline, and episodes the re-computed commands
    fail where the recorded ones succeed), hand commands in collision, not
    reproducing the recording, share of steps the Corrector had to fall back on, largest correction."""
    o = entry["overall"]
    steps = max(int(o.get("steps", 0)), 1)
    return (
        len(entry.get("regressions", [])) + len(entry.get("physics", {}).get("regressions", [])),
        float(o.get("collision_after_frac", 0.0)),
        not entry.get("bit_identical", True),
        int(o.get("fallback", 0)) / steps,
        float(o.get("deviation_max_rad", 0.0)),
    )


def _session_baselines(baseline: dict | None) -> dict[str, dict]:
    """The baseline's sessions by path and by file name (a corpus evaluated from another folder)."""
    out: dict[str, dict] = {}
    for s in (baseline or {}).get("sessions", []):
        out.setdefault(Path(s["session"]).name, s)
        out[s["session"]] = s
    return out


def evaluate_corpus(sessions: list[str | Path], models=None, rig=None, baseline: dict | None = None,
                    tolerances: Tolerances | None = None, executor=None, plots: str | Path | None = None,
                    on_done: Callable[[Outcome], None] | None = None, physics: bool = False) -> CorpusEvaluation:
    """Re-run every session (executor None: one after another in this process) and build the report."""
    started = time.perf_counter()
    paths = [str(Path(p).resolve()) for p in sessions]
    labels = [str(p) for p in sessions]
    job = EvalJob(str(Path(models).resolve()) if models else None, str(Path(rig).resolve()) if rig else None,
                  str(Path(plots).resolve()) if plots else None, physics)
    done = on_done or (lambda o: None)
    if executor is None:
        outcomes = []
        for i, (path, label) in enumerate(zip(paths, labels)):
            result = run_task(
                eval_one, job, path, label, 1, {}, lambda e: None
            )  # no fault injection here: it would end this process
            o = (
                Outcome(i, label, value=result[1])
                if result[0] == "done"
                else Outcome(i, label, error=result[2], kind=result[1], where=result[3])
            )
            outcomes.append(o)
            done(o)
        how = {"executor": "in-process", "workers": 1}
    else:
        outcomes = executor.map(eval_one, job, paths, labels=labels, on_done=done)
        how = {"executor": executor.name, "workers": executor.workers}

    tolerances = tolerances or default_tolerances()
    entries = []
    for o in outcomes:
        if not o.ok:
            continue
        entry = dict(o.value)
        entry["session"] = labels[o.index]
        entries.append(entry)
    report = make_report(
        [
            (
                e["session"],
                {"overall": e["overall"], "episodes": e["episodes"]},
                {k: v for k, v in e.items() if k not in ("session", "overall", "episodes")},
            )
            for e in entries
        ]
    )
    if baseline is not None:
        theirs = _session_baselines(baseline)
        for s in report["sessions"]:
            base = theirs.get(s["session"]) or theirs.get(Path(s["session"]).name)
            if base is not None:
                s["regressions"] = [r.describe() for r in compare(base, s, tolerances)]
    report["sessions"].sort(key=badness, reverse=True)
    for rank, s in enumerate(report["sessions"], 1):
        s["rank"] = rank
    failed = {labels[o.index]: str(o.exception()) for o in outcomes if not o.ok}
    report["failed"] = [{"session": k, "error": v} for k, v in failed.items()]
    wall = time.perf_counter() - started
    report["corpus"] = {"sessions": len(outcomes), "evaluated": len(entries), "failed": len(failed), **how,
                        "wall_s": wall,
                        "wall_realtime_x": report["overall"].get("duration_s", 0.0) / wall if wall > 0 else 0.0}
    regressions = compare(baseline, report, tolerances) if baseline is not None else None
    written = []
    if plots:
        from teleprev.evaluation.plots import plot_corpus

        written = [p for s in report["sessions"] for p in map(Path, s.get("plots", []))]
        if len(outcomes) > 1:
            written.append(plot_corpus(report, plots))
    return CorpusEvaluation(report, regressions, failed, written)


_COLUMNS = (
    ("steps", "steps", "{}"),
    ("collision_after_frac", "in coll.", "{:.1%}"),
    ("collision_before_frac", "fixed", "{:.1%}"),
    ("fallback", "fallback", "{}"),
    ("deviation_max_rad", "corr. max", "{:.3f}"),
    ("latency_ms_p99", "p99 ms", "{:.2f}"),
)


def corpus_table(report: dict, limit: int | None = None):
    """A rich Table: one row per session, worst first (failed sessions above all), `limit` rows at most.
    The regressions column is there when a baseline was given (the sessions carry "regressions")."""
    from rich.table import Table

    sessions, failed = report["sessions"], report.get("failed", [])
    total = len(sessions) + len(failed)
    shown = total if limit is None else min(limit, total)
    with_baseline = any("regressions" in s for s in sessions)
    title = f"{total} sessions, worst first" + (
        f" (the {shown} worst shown; the report has all)" if shown < total else ""
    )
    table = Table(title=title, title_justify="left")
    table.add_column("#", justify="right")
    table.add_column(
        "session",
        no_wrap=True,
        min_width=min(max((len(Path(s["session"]).name) for s in sessions + failed), default=7), 24),
    )
    for _, label, _ in _COLUMNS:
        table.add_column(label, justify="right")
    table.add_column("repro.", justify="center")
    if with_baseline:
        table.add_column("regressed")
    rows = [("", Path(f["session"]).name, *[""] * len(_COLUMNS), "[red]failed[/]", *([""] if with_baseline else []))
            for f in failed]
    for s in sessions:
        o, regs = s["overall"], s.get("regressions")
        rows.append(
            (
                str(s["rank"]),
                Path(s["session"]).name,
                *[fmt.format(o[key]) if key in o else "" for key, _, fmt in _COLUMNS],
                "[green]yes[/]" if s.get("bit_identical") else "[yellow]no[/]",
                *([] if not with_baseline else ["-" if regs is None else f"[red]{len(regs)}[/]" if regs else "0"]),
            )
        )
    for row in rows[:shown]:
        table.add_row(*row)
    table.caption = (
        "in coll.: hand commands in self-collision; fixed: steps the Corrector changed; corr. max: largest "
        "correction (rad); repro.: reproduces the recorded commands bit for bit"
        + (
            "; regressed: metrics past their tolerance against the same session in the baseline"
            if with_baseline
            else ""
        )
    )
    return table


def print_corpus(console, result: CorpusEvaluation, limit: int | None = None) -> None:
    report = result.report
    console.print(corpus_table(report, limit))
    o, c = report["overall"], report["corpus"]
    console.print(
        f"evaluated {o.get('duration_s', 0):.1f} s of recording from {c['evaluated']} session(s) in "
        f"{c['wall_s']:.1f} s "
        f"({c['wall_realtime_x']:.1f}x real time, {c['executor']}, {c['workers']} worker(s))",
        highlight=False,
    )
    if result.failed:
        from rich.markup import escape

        console.print(f"[bold red]{len(result.failed)} session(s) could not be evaluated:[/]")
        for why in result.failed.values():
            console.print(f"  [red]{escape(why)}[/]", highlight=False)
    regressed = [s for s in report["sessions"] if s.get("regressions")]
    for s in regressed[: limit or len(regressed)]:
        console.print(f"{Path(s['session']).name}: " + "; ".join(s["regressions"]), highlight=False)
    played = [s["physics"] for s in report["sessions"] if s.get("physics")]
    if played:
        episodes = [e for p in played for e in p["episodes"]]
        console.print(f"physics: {len(episodes)} episode(s) played; with the recorded commands "
                      f"{sum(e['replayed'] == 'success' for e in episodes)} succeed, with the re-computed ones "
                      f"{sum(e['recomputed'] == 'success' for e in episodes)}; recorded marks reproduced: "
                      f"{sum(e['agree'] for e in episodes)}/{len(episodes)}", highlight=False)
    if result.regressions is not None:
        if result.regressions:
            console.print(f"[bold red]{len(result.regressions)} regression(s) overall:[/]")
            for r in result.regressions:
                console.print(f"  [red]{r.describe()}[/]")
        else:
            console.print("[bold green]no regression against the baseline[/]")
