"""`teleprev eval` as a function: re-run sessions, measure, compare with a baseline."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from teleprev.evaluation.metrics import session_metrics
from teleprev.evaluation.report import Regression, Tolerances, compare, default_tolerances, make_report
from teleprev.evaluation.reproduce import Rerun, rerun_session


@dataclass
class Evaluation:
    report: dict
    reruns: list[Rerun]
    regressions: list[Regression] | None = None

    @property
    def outcome_regressions(self) -> list[str]:
        """With physics: the episodes the re-computed commands turn from success to failure (physics.py)."""
        return outcome_regressions(self.report)


def outcome_regressions(report: dict) -> list[str]:
    """The physics plays' regressions of a report's sessions, each naming its session and episode."""
    return [f"{Path(s['session']).name}: {r}" for s in report["sessions"] for r in s.get("physics", {}).get(
        "regressions", [])]


def evaluate(sessions: list[str | Path], models=None, rig=None, baseline: dict | None = None,
             tolerances: Tolerances | None = None, physics: bool = False) -> Evaluation:
    """Re-run and measure each session; with `physics`, also play it into the physics world, episode by
    episode, with the recorded and with the re-computed commands (teleprev/evaluation/physics.py)."""
    from teleprev.robot.collision import SelfCollisionChecker
    from teleprev.robot.model import load_robot

    results, reruns = [], []
    checkers: dict[str, SelfCollisionChecker] = {}  # by hand URDF: sessions may come from different rigs
    for path in sessions:
        r = rerun_session(path, models, rig)
        hand = r.effector.hand_urdf
        if r.effector.self_colliding and hand not in checkers:
            checkers[hand] = SelfCollisionChecker(load_robot(hand))
        m = session_metrics(r, checkers[hand] if r.effector.self_colliding else None)
        facts = {
            "bit_identical": bool(m["overall"].get("reproduced", False)),
            "models": {True: "as recorded", False: "different from the recording", None: "unknown"}[r.models_match],
            "rig": r.rig_source,
            "notes": r.notes,
        }
        if physics:
            from teleprev.evaluation.physics import play_session

            facts["physics"] = play_session(r).to_report()
        results.append((str(path), m, facts))
        reruns.append(r)
    report = make_report(results)
    regressions = compare(baseline, report, tolerances or default_tolerances()) if baseline is not None else None
    return Evaluation(report, reruns, regressions)
