"""`teleprev audit`: does a recorded session's command stream keep to what the robot can follow?

For each command stream (/command/arm, /command/hand) against the limits of the session's rig (the
rig's [pipeline] keys, else teleprev/robot/limits.py and the URDF):

    position   inside the URDF's joint limits
    speed      first divided difference on the command stamps
    accel      2 x the second divided difference (an acceleration the commands pass through, between them)
    jerk       6 x the third divided difference (arm)
    collisions hand commands in self-collision (exact check, plain shapes), and hand command segments
               that pass through one (checked at link motions of at most SWEPT_STEP_M)

and, for the hand's measured state, how many samples were in self-collision. Ratios are measured /
limit: above 1 is a violation (a tolerance of 1e-6 absorbs rounding). Runs of commands more than
RUN_GAP_S apart are measured separately (a new engage starts from rest).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.errors import SessionError

RUN_GAP_S = 0.06  # as the pipeline's RESUME_GAP_NS: after a pause this long, commands start again from rest
SWEPT_STEP_M = 0.0005
TOLERANCE = 1e-6


@dataclass
class StreamAudit:
    topic: str
    commands: int = 0
    position_outside: int = 0
    speed_max: float = 0.0
    speed_limit: float = 0.0
    accel_max: float = 0.0
    accel_limit: float = 0.0
    jerk_max: float = 0.0
    jerk_limit: float | None = None
    colliding: int | None = None  # commands in self-collision (hand)
    swept_colliding: int | None = None  # command segments through a self-collision (hand)

    @property
    def ratios(self) -> dict[str, float]:
        out = {"speed": self.speed_max / self.speed_limit if self.speed_limit else 0.0,
               "accel": self.accel_max / self.accel_limit if self.accel_limit else 0.0}
        if self.jerk_limit:
            out["jerk"] = self.jerk_max / self.jerk_limit
        return out

    @property
    def violations(self) -> list[str]:
        out = [f"{k} {v:.3f} x the limit" for k, v in self.ratios.items() if v > 1.0 + TOLERANCE]
        if self.position_outside:
            out.append(f"{self.position_outside} commands outside the joint limits")
        if self.colliding:
            out.append(f"{self.colliding} commands in self-collision")
        if self.swept_colliding:
            out.append(f"{self.swept_colliding} command segments through a self-collision")
        return out


@dataclass
class AuditReport:
    session: str
    streams: list[StreamAudit] = field(default_factory=list)
    hand_state_samples: int = 0
    hand_state_colliding: int | None = None

    @property
    def ok(self) -> bool:
        return not any(s.violations for s in self.streams) and not self.hand_state_colliding

    def as_dict(self) -> dict:
        return {"session": self.session, "ok": self.ok, "hand_state_samples": self.hand_state_samples,
                "hand_state_colliding": self.hand_state_colliding,
                "streams": [{**asdict(s), "ratios": s.ratios, "violations": s.violations} for s in self.streams]}


def divided_differences(t_ns: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Speed, acceleration and jerk (1!, 2!, 3! times the divided differences) of samples q at stamps t_ns."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    t = (t_ns - t_ns[0]) / 1e9  # difference integer nanoseconds first: epoch seconds lose ~1e-7 s in float64
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    f2 = np.diff(v, axis=0) / (t[2:] - t[:-2])[:, None]
    f3 = np.diff(f2, axis=0) / (t[3:] - t[:-3])[:, None]
    return v, 2.0 * f2, 6.0 * f3


def _runs(t_ns: np.ndarray) -> list[slice]:
    breaks = np.flatnonzero(np.diff(t_ns) > RUN_GAP_S * 1e9) + 1
    edges = [0, *breaks.tolist(), len(t_ns)]
    return [slice(a, b) for a, b in zip(edges, edges[1:]) if b > a]


def _measure(audit: StreamAudit, t_ns: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> None:
    audit.commands = len(t_ns)
    audit.position_outside = int(((q < lower - 1e-9) | (q > upper + 1e-9)).any(axis=1).sum())
    for run in _runs(t_ns):
        if run.stop - run.start < 2:
            continue
        v, a, j = divided_differences(t_ns[run], q[run])
        audit.speed_max = max(audit.speed_max, float(np.abs(v).max()))
        if len(a):
            audit.accel_max = max(audit.accel_max, float(np.abs(a).max()))
        if len(j):
            audit.jerk_max = max(audit.jerk_max, float(np.abs(j).max()))


def swept_colliding(checker, reach: np.ndarray, q: np.ndarray, step_m: float = SWEPT_STEP_M) -> int:
    """Segments q[i] -> q[i+1] with a configuration in self-collision, checked where links moved <= step_m."""
    bad = 0
    for q0, q1 in zip(q[:-1], q[1:]):
        n = max(1, int(np.ceil(float((reach @ np.abs(q1 - q0)).max()) / step_m)))
        points = q0 + (np.arange(1, n) / n)[:, None] * (q1 - q0)
        if len(points) and checker.pair_matrix(points).any():
            bad += 1
    return bad


def _joint_samples(reader, topic: str) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    from teleprev.messages import JointSample

    msgs = [m.payload for m in reader.messages([topic]) if isinstance(m.payload, JointSample)]
    if not msgs:
        return np.zeros(0, dtype=np.int64), np.zeros((0, 0)), ()
    return (np.array([m.stamp_ns for m in msgs], dtype=np.int64), np.array([m.positions for m in msgs], dtype=float),
            msgs[0].names)


def audit_session(path: str | Path, rig_path: str | Path | None = None) -> AuditReport:
    from teleprev.live.build import motion_limits
    from teleprev.rig import load_recorded_rig, load_rig
    from teleprev.session.reader import SessionReader

    path = Path(path)
    reader = SessionReader(path)
    meta = reader.metadata
    rig = load_rig(rig_path) if rig_path else load_recorded_rig(meta, path)
    if rig is None:
        raise SessionError("the session does not carry its rig (metadata 'rig'); pass --config RIG", str(path))
    limits = motion_limits(rig)
    report = AuditReport(str(path))
    for topic, side in ((topics.COMMAND_ARM, "arm"), (topics.COMMAND_HAND, "hand")):
        t, q, names = _joint_samples(reader, topic) if topic in reader.topics else (np.zeros(0, np.int64), None, ())
        lim = limits[side]
        audit = StreamAudit(topic, speed_limit=float(lim["velocity"].min()), accel_limit=float(lim["acceleration"]),
                            jerk_limit=lim.get("jerk"))
        if len(t):
            if names != lim["names"]:
                raise SessionError(f"{topic} commands joints {names}, the rig's robot has {lim['names']}", str(path))
            _measure(audit, t, q, lim["lower"], lim["upper"])
            if side == "hand" and lim.get("checker") is not None:
                audit.colliding = int(lim["checker"].pair_matrix(q).any(axis=1).sum())
                audit.swept_colliding = sum(swept_colliding(lim["checker"], lim["reach"], q[run]) for run in _runs(t))
        report.streams.append(audit)
    hand_limits = limits["hand"]
    state_topics = [tp for tp in reader.topics if tp.startswith("/hand/") and tp.endswith("/state")]
    if state_topics and hand_limits.get("checker") is not None:
        _, q, _ = _joint_samples(reader, state_topics[0])
        report.hand_state_samples = len(q)
        report.hand_state_colliding = int(hand_limits["checker"].pair_matrix(q).any(axis=1).sum()) if len(q) else 0
    return report


def print_report(report: AuditReport, console) -> None:
    from rich.table import Table

    for s in report.streams:
        table = Table(title=f"{report.session} {s.topic}: {s.commands} commands", title_justify="left")
        table.add_column("check")
        table.add_column("measured", justify="right")
        table.add_column("limit", justify="right")
        table.add_column("ratio", justify="right")
        ratios = s.ratios
        for name, measured, limit in (("speed", s.speed_max, s.speed_limit), ("acceleration", s.accel_max, s.accel_limit),
                                      ("jerk", s.jerk_max, s.jerk_limit)):
            if limit:
                r = ratios[name if name != "acceleration" else "accel"]
                style = "red" if r > 1 + TOLERANCE else "green"
                table.add_row(name, f"{measured:.4g}", f"{limit:.4g}", f"[{style}]{r:.3f}[/]")
        table.add_row("outside joint limits", str(s.position_outside), "0", "")
        if s.colliding is not None:
            table.add_row("in self-collision", str(s.colliding), "0", "")
            table.add_row("segments through a self-collision", str(s.swept_colliding), "0", "")
        console.print(table)
    if report.hand_state_colliding is not None:
        console.print(f"measured hand state in self-collision: {report.hand_state_colliding} of {report.hand_state_samples} samples")
    console.print("[green]audit passed[/]" if report.ok else "[red]audit failed[/]: " + "; ".join(
        f"{s.topic}: {v}" for s in report.streams for v in s.violations) + (
        f"; hand state in self-collision {report.hand_state_colliding}x" if report.hand_state_colliding else ""))


def write_json(reports: list[AuditReport], out: Path) -> None:
    out.write_text(json.dumps([r.as_dict() for r in reports], indent=2))
