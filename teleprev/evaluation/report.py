"""Evaluation reports: the JSON that CI keeps, the table on screen, and the regression gate.

A tolerances file (TOML) says how far each metric may move from the baseline before it counts as a
regression, in absolute or relative terms, and in which direction moving is bad:

    [metrics.collision_after_frac]
    abs = 0.0                 # any increase fails
    [metrics.deviation_mean_rad]
    abs = 0.01
    rel = 0.10                # whichever is larger
    [metrics.latency_ms_p99]
    rel = 0.5
    worse = "higher"          # "higher" (default), "lower" or "either"
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from rich.console import Console
from rich.table import Table

from teleprev.config import from_table, read_toml
from teleprev.errors import ConfigError

REPORT_VERSION = 1


@dataclass(frozen=True)
class Tolerance:
    abs: float = 0.0
    rel: float = 0.0
    worse: Literal["higher", "lower", "either"] = "higher"


@dataclass(frozen=True)
class Tolerances:
    metrics: dict[str, Tolerance] = field(default_factory=dict)


@dataclass(frozen=True)
class Regression:
    metric: str
    baseline: float
    now: float
    allowed: float

    def describe(self) -> str:
        return (f"{self.metric}: {self.baseline:.6g} -> {self.now:.6g} "
                f"(moved {self.now - self.baseline:+.6g}, allowed {self.allowed:.6g})")


def load_tolerances(path: str | Path) -> Tolerances:
    return from_table(Tolerances, read_toml(path), str(path))


def default_tolerances() -> Tolerances:
    return load_tolerances(Path(__file__).with_name("tolerances.toml"))


def make_report(sessions: list[tuple[str, dict, dict]]) -> dict:
    """sessions: (path, metrics from session_metrics, facts: bit_identical etc.). Overall = step-weighted."""
    overall: dict = {}
    total = sum(m["overall"]["steps"] for _, m, _ in sessions) or 1
    for key in sessions[0][1]["overall"] if sessions else []:
        values = [m["overall"].get(key) for _, m, _ in sessions]
        if all(isinstance(v, bool) for v in values):
            overall[key] = all(values)
        elif key in ("steps", "untouched", "ccn", "fallback", "dropped_inputs"):
            overall[key] = int(sum(values))
        elif key.endswith("_max") or key.endswith("_p99"):
            overall[key] = max(values)
        elif key in ("duration_s", "rerun_wall_s"):
            overall[key] = float(sum(values))
        else:
            overall[key] = float(sum(v * m["overall"]["steps"] for v, (_, m, _) in zip(values, sessions)) / total)
    if sessions:
        overall["realtime_x"] = overall["duration_s"] / overall["rerun_wall_s"] if overall.get("rerun_wall_s") else 0.0
    return {
        "report_version": REPORT_VERSION,
        "overall": overall,
        "sessions": [
            {"session": path, **facts, "overall": m["overall"], "episodes": m["episodes"]}
            for path, m, facts in sessions
        ],
    }


def compare(baseline: dict, report: dict, tolerances: Tolerances) -> list[Regression]:
    """Metrics of `report` that moved past their tolerance from `baseline` (overall figures)."""
    if "overall" not in baseline:
        raise ConfigError("not a teleprev eval report (no 'overall')", "baseline")
    out = []
    for metric, tol in tolerances.metrics.items():
        if metric not in baseline["overall"] or metric not in report["overall"]:
            continue
        b, n = baseline["overall"][metric], report["overall"][metric]
        if isinstance(b, bool) or isinstance(n, bool):
            if b and not n:
                out.append(Regression(metric, float(b), float(n), 0.0))
            continue
        allowed = max(tol.abs, tol.rel * abs(b))
        moved = n - b
        bad = {"higher": moved > allowed, "lower": -moved > allowed, "either": abs(moved) > allowed}[tol.worse]
        if bad:
            out.append(Regression(metric, float(b), float(n), allowed))
    return out


def write_report(report: dict, path: str | Path) -> None:
    Path(path).write_text(json.dumps(report, indent=2, default=float))


def read_report(path: str | Path) -> dict:
    try:
        return json.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError("no such report", str(path)) from None
    except json.JSONDecodeError as exc:
        raise ConfigError(f"not a JSON report ({exc})", str(path)) from None


_SHOWN = (
    ("steps", "steps", "{}"),
    ("collision_before_frac", "hand in collision before correction", "{:.1%}"),
    ("collision_after_frac", "hand commands in collision", "{:.1%}"),
    ("deviation_mean_rad", "correction mean (rad)", "{:.4f}"),
    ("deviation_max_rad", "correction max (rad)", "{:.4f}"),
    ("untouched", "untouched", "{}"),
    ("ccn", "ccn", "{}"),
    ("fallback", "fallback", "{}"),
    ("arm_speed_max", "arm speed max (rad/s)", "{:.3f}"),
    ("hand_speed_max", "hand speed max", "{:.3f}"),
    ("arm_accel_max", "arm acceleration max (rad/s^2)", "{:.3g}"),
    ("hand_accel_max", "hand acceleration max", "{:.3g}"),
    ("arm_jerk_max", "arm jerk max (rad/s^3)", "{:.3g}"),
    ("hand_jerk_max", "hand jerk max", "{:.3g}"),
    ("latency_ms_p50", "step p50 (ms)", "{:.3f}"),
    ("latency_ms_p99", "step p99 (ms)", "{:.3f}"),
    ("held_frac", "held input", "{:.1%}"),
    ("dropped_inputs", "dropped inputs", "{}"),
    ("reproduced", "reproduces the recording", "{}"),
)


def print_report(console: Console, report: dict, regressions: list[Regression] | None = None) -> None:
    """One table per session: a row per metric, a column for the session and each of its episodes."""
    for s in report["sessions"]:
        table = Table(title=Path(s["session"]).name, title_justify="left")
        table.add_column("metric", no_wrap=True)
        table.add_column("session", justify="right", style="bold")
        for e in s["episodes"]:
            table.add_column(
                f"ep {e['episode']}\n{e['task']}" + ("\n(discarded)" if e["discarded"] else ""), justify="right"
            )
        for key, label, fmt in _SHOWN:
            cells = [s["overall"], *s["episodes"]]
            if any(key in c for c in cells):
                table.add_row(label, *[fmt.format(c[key]) if key in c else "" for c in cells])
        console.print(table)
    o = report["overall"]
    console.print(
        f"evaluated {o.get('duration_s', 0):.1f} s of recording in {o.get('rerun_wall_s', 0):.1f} s "
        f"({o.get('realtime_x', 0):.1f}x real time)"
    )
    for s in report["sessions"]:
        verdict = (
            "[green]reproduces the recorded commands bit for bit[/]"
            if s.get("bit_identical")
            else "[yellow]does not reproduce the recorded commands[/]"
        )
        console.print(f"{Path(s['session']).name}: {verdict}  (models {s.get('models', '?')}, rig {s.get('rig', '?')})")
    if regressions is not None:
        if regressions:
            console.print(f"[bold red]{len(regressions)} regression(s):[/]")
            for r in regressions:
                console.print(f"  [red]{r.describe()}[/]")
        else:
            console.print("[bold green]no regression against the baseline[/]")
