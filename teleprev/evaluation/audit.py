"""`teleprev audit`: does a recorded session's command stream, or a LeRobot dataset's `action` column,
keep to what the robot can follow?

For each command stream (/command/arm, /command/hand) against the limits of the session's rig (the
rig's [pipeline] keys, else teleprev/robot/limits.py and the URDF):

    position   inside the URDF's joint limits
    speed      first divided difference on the command stamps
    accel      2 x the second divided difference (an acceleration the commands pass through, between them)
    jerk       6 x the third divided difference (arm)
    tcp_speed  the flange's linear speed between consecutive commands, by FK, against the rig's
               arm_tcp_speed (teleprev/pipeline/tcp_speed.py; sessions of format 10 on: older formats
               did not cap it, and a dataset's actions are not checked)
               (teleprev/pipeline/derivatives.py: the definition eval and the benches use too)
    collisions hand commands in self-collision (exact check, plain shapes), and hand command segments
               that pass through one (checked at link motions of at most SWEPT_STEP_M)

and, for the hand's measured state, how many samples were in self-collision. Ratios are measured /
limit: above 1 is a violation (a tolerance of 1e-6 absorbs rounding). Commands more than RESUME_GAP_NS
apart start a new run, measured as the controller sees it: from rest on the last command before the pause
(a stream that resumes with a jump fails). A dataset's actions are taken as commands sent at its frames'
timestamps, each episode on its own.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.errors import SessionError
from teleprev.evaluation.controller_resets import ActuatorHistory
from teleprev.export.actions import is_dataset, read_actions
from teleprev.pipeline.derivatives import RESUME_GAP_NS, runs, stream_peaks

SWEPT_STEP_M = 0.0005
TCP_SPEED_FORMAT_VERSION = 10  # the first session format whose planner caps the flange's speed
TOLERANCE = 1e-6


@dataclass
class StreamAudit:
    topic: str
    commands: int = 0
    position_outside: int = 0
    not_finite: int = 0  # commands holding a NaN or infinite position (their differences measure nothing)
    speed_max: float = 0.0
    speed_limit: float = 0.0
    accel_max: float = 0.0
    accel_limit: float = 0.0
    jerk_max: float = 0.0
    jerk_limit: float | None = None
    tcp_speed_max: float = 0.0  # m/s, the flange's (arm)
    tcp_speed_limit: float | None = None  # None: not checked
    colliding: int | None = None  # commands in self-collision (hand)
    swept_colliding: int | None = None  # command segments through a self-collision (hand)
    rounding: dict[str, float] = field(default_factory=dict)  # per check: how much the values' storage may add

    @property
    def ratios(self) -> dict[str, float]:
        out = {"speed": self.speed_max / self.speed_limit if self.speed_limit else 0.0,
               "accel": self.accel_max / self.accel_limit if self.accel_limit else 0.0}
        if self.jerk_limit:
            out["jerk"] = self.jerk_max / self.jerk_limit
        if self.tcp_speed_limit:
            out["tcp_speed"] = self.tcp_speed_max / self.tcp_speed_limit
        return out

    @property
    def violations(self) -> list[str]:
        out = [
            f"{k} {v:.3f} x the limit"
            for k, v in self.ratios.items()
            if v > 1.0 + TOLERANCE + self.rounding.get(k, 0.0)
        ]
        if self.not_finite:
            out.append(f"{self.not_finite} commands not finite (NaN or inf)")
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
    note: str = ""

    @property
    def ok(self) -> bool:
        return not any(s.violations for s in self.streams) and not self.hand_state_colliding

    def as_dict(self) -> dict:
        return {
            "session": self.session,
            "ok": self.ok,
            "note": self.note,
            "hand_state_samples": self.hand_state_samples,
            "hand_state_colliding": self.hand_state_colliding,
            "streams": [{**asdict(s), "ratios": s.ratios, "violations": s.violations} for s in self.streams],
        }


def _runs(t_ns: np.ndarray) -> list[slice]:
    return runs(t_ns, RESUME_GAP_NS)


def _measure(audit: StreamAudit, t_ns: np.ndarray, q: np.ndarray, lower: np.ndarray, upper: np.ndarray,
             from_rest: bool, rests) -> None:
    audit.commands = len(t_ns)
    audit.position_outside = int(((q < lower - 1e-9) | (q > upper + 1e-9)).any(axis=1).sum())
    finite = np.isfinite(q).all(axis=1)
    audit.not_finite = int((~finite).sum())
    if audit.not_finite:  # the peaks are measured between the finite commands; those are violations of their own
        t_ns, q, rests = t_ns[finite], q[finite], None
    audit.speed_max, audit.accel_max, audit.jerk_max = stream_peaks(t_ns, q, from_rest, rests=rests).worst()


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


def recorded_rig(path: Path, meta: dict, rig_path: str | Path | None):
    """The rig whose limits apply: `rig_path`, else the one the session carries in its metadata."""
    from teleprev.rig import load_recorded_rig, load_rig

    rig = load_rig(rig_path) if rig_path else load_recorded_rig(meta, path)
    if rig is None:
        raise SessionError("the session does not carry its rig (metadata 'rig'); pass --config RIG", str(path))
    return rig


def actuator_history(reader, side: str, names: tuple[str, ...], device: str = "") -> ActuatorHistory:
    """The measured states and (re)connections of the session's actuator of one side ("arm", "hand"): the
    device named, else the first of its kind."""
    from teleprev.messages import Event, JointSample

    history = ActuatorHistory()
    kind = "arm" if side == "arm" else "hand"
    states = sorted(tp for tp in reader.topics if tp.startswith(f"/{kind}/{device}") and tp.endswith("/state"))
    if not states:
        return history
    device = states[0].split("/")[2]
    wanted = [states[0]] + ([topics.DEVICE_EVENT] if topics.DEVICE_EVENT in reader.topics else [])
    for msg in reader.messages(wanted):
        p = msg.payload
        if isinstance(p, JointSample):
            try:
                history.add_state(p.stamp_ns, [p.positions[p.names.index(n)] for n in names])
            except ValueError:
                continue
        elif isinstance(p, Event) and p.data.get("device") == device and p.data.get("event") == "connected":
            history.connects_ns.append(msg.log_time_ns)
    return history


def audit_stream(topic: str, side: str, limits: dict, t_ns: np.ndarray, q: np.ndarray | None,
                 from_rest: bool = True, rests=None, tcp_speed: bool = False) -> StreamAudit:
    """One command stream (stamps, positions in the order of limits[side]['names']) against its limits;
    `from_rest`: each run as a controller starts it (commands; not a dataset's actions), `rests`: where
    (ActuatorHistory.for_stream); `tcp_speed`: the arm's flange speed too, where the rig caps it."""
    lim = limits[side]
    tcp = lim.get("tcp") if tcp_speed else None
    audit = StreamAudit(topic, speed_limit=float(lim["velocity"].min()), accel_limit=float(lim["acceleration"]),
                        jerk_limit=lim.get("jerk"), tcp_speed_limit=tcp.cap if tcp is not None else None)
    if len(t_ns):
        _measure(audit, t_ns, q, lim["lower"], lim["upper"], from_rest, rests)
        if tcp is not None:
            finite = np.isfinite(q).all(axis=1)
            t_f, q_f = t_ns[finite], q[finite]
            audit.tcp_speed_max = max((float(tcp.speeds(t_f[run], q_f[run]).max(initial=0.0))
                                       for run in _runs(t_f)), default=0.0)
        if side == "hand" and lim.get("checker") is not None:
            audit.colliding = int(lim["checker"].pair_matrix(q).any(axis=1).sum())
            audit.swept_colliding = sum(swept_colliding(lim["checker"], lim["reach"], q[run]) for run in _runs(t_ns))
    return audit


def _command_streams(rig) -> list[tuple[str, str, dict, str]]:
    """(topic, "arm" | "hand", its limits, its device) of each command stream a session of `rig` records: a
    bimanual rig's per side (/command/left/arm, against the left side's limits)."""
    from teleprev.assembly import motion_limits
    from teleprev.pipeline.bimanual import side_topic
    from teleprev.rig import side_rig

    if not rig.bimanual:
        limits = motion_limits(rig)
        return [(topics.COMMAND_ARM, "arm", limits, ""), (topics.COMMAND_HAND, "hand", limits, "")]
    out = []
    for side, s in rig.sides.items():
        limits = motion_limits(side_rig(rig, side))
        out += [(side_topic(topic, side), kind, limits, s.devices[kind])
                for topic, kind in ((topics.COMMAND_ARM, "arm"), (topics.COMMAND_HAND, "hand"))]
    return out


def audit_session(path: str | Path, rig_path: str | Path | None = None) -> AuditReport:
    from teleprev.assembly import motion_limits
    from teleprev.evaluation.reproduce import recorded_format
    from teleprev.rig import side_rig
    from teleprev.session.reader import SessionReader

    path = Path(path)
    with SessionReader(path) as reader:
        rig = recorded_rig(path, reader.metadata, rig_path)
        report = AuditReport(str(path))
        tcp_speed = recorded_format(reader.metadata) >= TCP_SPEED_FORMAT_VERSION
        for topic, side, limits, device in _command_streams(rig):
            t, q, names = _joint_samples(reader, topic) if topic in reader.topics else (np.zeros(0, np.int64), None, ())
            if len(t) and names != limits[side]["names"]:
                raise SessionError(
                    f"{topic} commands joints {names}, the rig's robot has {limits[side]['names']}", str(path)
                )
            history = actuator_history(reader, side, limits[side]["names"], device) if len(t) else None
            report.streams.append(
                audit_stream(topic, side, limits, t, q, rests=history.for_stream(t) if history else None,
                             tcp_speed=tcp_speed and side == "arm")
            )
        state_topics = [tp for tp in reader.topics if tp.startswith("/hand/") and tp.endswith("/state")]
        checks = [(state_topics[0], motion_limits(rig)["hand"])] if state_topics and not rig.bimanual else \
            [(f"/hand/{s.devices['hand']}/state", motion_limits(side_rig(rig, n))["hand"]) for n, s in rig.sides.items()
             if f"/hand/{s.devices['hand']}/state" in reader.topics]
        for topic, hand_limits in checks:
            if hand_limits.get("checker") is None:
                continue
            _, q, _ = _joint_samples(reader, topic)
            report.hand_state_samples += len(q)
            colliding = int(hand_limits["checker"].pair_matrix(q).any(axis=1).sum()) if len(q) else 0
            report.hand_state_colliding = (report.hand_state_colliding or 0) + colliding
        return report


def audit_dataset(root: str | Path, rig_path: str | Path | None) -> AuditReport:
    """The `action` column of a LeRobot dataset, per episode, as commands sent at the frames' timestamps,
    against a rig's limits (joints matched as read_actions says); a bimanual rig's each side against its own
    ("action[left arm]" ...)."""
    from teleprev.assembly import motion_limits
    from teleprev.rig import load_rig, side_rig

    root = Path(root)
    if rig_path is None:
        raise SessionError(
            "a dataset does not carry its rig: pass --config RIG (the robot whose limits apply)", str(root)
        )
    rig = load_rig(rig_path)
    sides = [(side, motion_limits(side_rig(rig, side))) for side in rig.sides] if rig.bimanual else \
        [("", motion_limits(rig))]
    report = AuditReport(str(root))
    for side, limits in sides:
        data = read_actions(root, limits, side)
        report.note = report.note or data.note
        report.streams += _audit_actions(data, limits, f"{side} " if side else "")
    return report


def _audit_actions(data, limits: dict, label: str) -> list[StreamAudit]:
    """One robot's arm and end-effector columns of a dataset's actions (DatasetActions), episode by episode."""
    stamps, action = data.stamps, data.action
    # The actions are stored as float32: rounded, each value moves by up to half an ulp, which a divided
    # difference of order k at the frames' spacing h can grow to 2^k x that / h^k.
    half_ulp = 2.0 ** -24 * (float(np.abs(action).max()) if action.size else 0.0)
    spacing = np.diff(np.unique(stamps)).min() / 1e9 if len(np.unique(stamps)) > 1 else 1.0
    arm_topic, hand_topic = f"action[{label}arm]", f"action[{label}end effector]"
    arm, hand = StreamAudit(arm_topic), StreamAudit(hand_topic)
    for ep in np.unique(data.episodes):
        t, q = data.episode(int(ep))
        t = t + int(ep) * 3_600_000_000_000  # episodes an hour apart: never one run
        merge(arm, audit_stream(arm_topic, "arm", limits, t, q[:, data.arm_cols], from_rest=False))
        merge(hand, audit_stream(hand_topic, "hand", limits, t, q[:, data.hand_cols], from_rest=False))
    for total in (arm, hand):
        for name, order, limit in (("speed", 1, total.speed_limit), ("accel", 2, total.accel_limit),
                                   ("jerk", 3, total.jerk_limit)):
            if limit:
                total.rounding[name] = 2 ** order * half_ulp / spacing ** order / limit
    return [arm, hand]


def merge(total: StreamAudit, part: StreamAudit) -> None:
    """Fold one episode's audit into the stream's total (maxima and counts)."""
    total.commands += part.commands
    total.position_outside += part.position_outside
    total.not_finite += part.not_finite
    total.speed_max, total.speed_limit = max(total.speed_max, part.speed_max), part.speed_limit
    total.accel_max, total.accel_limit = max(total.accel_max, part.accel_max), part.accel_limit
    total.jerk_max, total.jerk_limit = max(total.jerk_max, part.jerk_max), part.jerk_limit
    total.tcp_speed_max, total.tcp_speed_limit = max(total.tcp_speed_max, part.tcp_speed_max), part.tcp_speed_limit
    if part.colliding is not None:
        total.colliding = (total.colliding or 0) + part.colliding
        total.swept_colliding = (total.swept_colliding or 0) + part.swept_colliding


def audit_path(path: str | Path, rig_path: str | Path | None = None) -> AuditReport:
    """A session file or a LeRobot dataset folder."""
    return audit_dataset(path, rig_path) if is_dataset(Path(path)) else audit_session(path, rig_path)


def print_report(report: AuditReport, console) -> None:
    from rich.markup import escape
    from rich.table import Table

    for s in report.streams:  # (escaped: a dataset's "action[arm]" is not rich markup)
        table = Table(title=escape(f"{report.session} {s.topic}: {s.commands} commands"), title_justify="left")
        table.add_column("check")
        table.add_column("measured", justify="right")
        table.add_column("limit", justify="right")
        table.add_column("ratio", justify="right")
        ratios = s.ratios
        for name, measured, limit in (
            ("speed", s.speed_max, s.speed_limit),
            ("acceleration", s.accel_max, s.accel_limit),
            ("jerk", s.jerk_max, s.jerk_limit),
            ("tcp_speed", s.tcp_speed_max, s.tcp_speed_limit),
        ):
            if limit:
                r = ratios[name if name != "acceleration" else "accel"]
                style = "red" if r > 1 + TOLERANCE else "green"
                table.add_row(name, f"{measured:.4g}", f"{limit:.4g}", f"[{style}]{r:.3f}[/]")
        table.add_row("outside joint limits", str(s.position_outside), "0", "")
        if s.not_finite:
            table.add_row("not finite (NaN, inf)", f"[red]{s.not_finite}[/]", "0", "")
        if s.colliding is not None:
            table.add_row("in self-collision", str(s.colliding), "0", "")
            table.add_row("segments through a self-collision", str(s.swept_colliding), "0", "")
        console.print(table)
    if report.note:
        console.print(f"[yellow]{report.note}[/]")
    if report.hand_state_colliding is not None:
        console.print(
            f"measured hand state in self-collision: {report.hand_state_colliding} of {report.hand_state_samples} "
            "samples"
        )
    console.print("[green]audit passed[/]" if report.ok else "[red]audit failed[/]: " + escape("; ".join(
        f"{s.topic}: {v}" for s in report.streams for v in s.violations)) + (
        f"; hand state in self-collision {report.hand_state_colliding}x" if report.hand_state_colliding else ""))


def write_json(reports: list[AuditReport], out: Path) -> None:
    out.write_text(json.dumps([r.as_dict() for r in reports], indent=2))
