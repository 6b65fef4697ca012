"""Recorded sessions against the emulated arm and hand, measured at the emulators' receiving end
(bench/hardware.py's figures under load).

Each session is `teleprev record` with the simulated operator, the sim camera, the emulated xArm controller
and the emulated LEAP Hand bus (the real SDKs), its preview rendering into a pseudo-terminal, unattended:
engaged after a few seconds for one episode. The emulators stand for hardware outside this machine: each
runs in a process of its own with real-time priority below the command path's (where permitted), so that
the load on this machine delays the commands on their way, not the emulator that stamps their arrival.

Per session, the arm's targets as the controller received them are matched one to one, in order, with the
ticks' commands on /command/arm (same values, float32 on the wire) and measured:
    gap       between two targets of one engaged run (the first after an engage starts a run)
    late      arrival - the tick's planned instant (its stamp less how late the sender woke): the time
              from the sender's schedule to the controller
    per cycle targets that arrived in one servo cycle of the controller
and the controller's own judgement of what it ran (speed, acceleration, jerk ratios), its faults, and the
hand's goal writes, read misses and faults.
"""

from __future__ import annotations

import json
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


# ---- one session ------------------------------------------------------------------------------------------
@dataclass
class WireSession:
    returncode: int
    gaps_ms: list[float] = field(default_factory=list)
    late_ms: list[float] = field(default_factory=list)
    per_cycle_max: int = 0
    ratios: list[tuple[float, float, float]] = field(default_factory=list)
    box_faults: list[str] = field(default_factory=list)
    matched: bool = False  # every recorded arm command arrived, in order, with its values
    arm_commands: int = 0
    arm_errors: list[str] = field(default_factory=list)
    hand_errors: list[str] = field(default_factory=list)
    arm_refused: int = 0
    hand_refused: int = 0
    hand_commands: int = 0
    goal_writes: int = 0
    corrupt_requests: int = 0
    unknown_registers: int = 0
    hand_reads: int = 0
    read_misses: int = 0
    engaged_s: float = 0.0
    roundtrip_ms: list[float] = field(default_factory=list)  # an arm write to the first state showing it
    recorded: bool = False
    write_ms: dict[str, list[float]] = field(default_factory=dict)  # per kind: a tick's sampling to its write
    notes: list[str] = field(default_factory=list)

    # Each device on its own evidence (a session that ends with exit 1 because the other device failed
    # still says how this one did).
    @property
    def xarm_ok(self) -> bool:
        return (self.recorded and self.matched and self.arm_commands > 0 and not self.arm_errors and not self.box_faults
                and self.arm_refused == 0 and self.unknown_registers == 0)

    @property
    def leap_ok(self) -> bool:
        return (self.recorded and not self.hand_errors and self.corrupt_requests == 0 and self.hand_refused == 0
                and self.hand_commands > 0 and self.goal_writes >= self.hand_commands)


def run_session(folder: Path, k: int, seconds: float, engage_after: float, preview=(80, 24)) -> WireSession:
    from bench.realtime import record
    from teleprev.emulators.dynamixel_bus import DynamixelBus
    from teleprev.emulators.xarm_controller import XArmController
    from tests.helpers.emulated_rig import EmulatorProcess, box_summary, bus_summary, sim_operator_rig

    box = EmulatorProcess(lambda: XArmController(host=None), "arm", box_summary)
    bus = EmulatorProcess(lambda: DynamixelBus(), "hand", bus_summary)
    rig, out = folder / f"wire_{k:02d}.toml", folder / f"wire_{k:02d}.mcap"
    rig.write_text(sim_operator_rig(box.keys, bus.keys))
    offset_ns = time.time_ns() - time.monotonic_ns()  # the session clock from monotonic (SessionClock)
    try:
        code = record(rig, out, seconds, 1, engage_after, preview)
    finally:
        arm, hand = box.finish(), bus.finish()
    return measure(out, code, arm, hand, offset_ns)


def measure(path: Path, code: int, arm: dict, hand: dict, offset_ns: int) -> WireSession:
    from teleprev import topics
    from teleprev.session.reader import SessionReader

    s = WireSession(code, box_faults=arm["faults"], ratios=arm["judged"], goal_writes=hand["goal_writes"],
                    corrupt_requests=hand["corrupt_requests"], unknown_registers=sum(arm["unknown"].values()))
    if not path.exists():
        s.notes.append(f"no session file (exit {code})")
        return s
    s.recorded = True
    with SessionReader(path) as reader:
        def read(topic):  # (a session that never engaged has no commands)
            return list(reader.messages([topic])) if topic in reader.topics else []

        states = [(m.log_time_ns, m.payload.positions) for m in read("/arm/arm/state")]
        ticks = [(m.payload.stamp_ns, m.payload.data) for m in read(topics.COMMAND_TICK)]
        wired = [m.payload for m in read(topics.COMMAND_WIRE)]
        # the commands that went out (/command/wire): a superseded one never reached the controller
        sent = {w.data["t_ns"] for w in wired if w.data["kind"] == "arm" and w.data["sent"]}
        commands = [m.payload for m in read(topics.COMMAND_ARM) if m.payload.stamp_ns in sent]
        engages = [m.log_time_ns for m in read(topics.MODE) if m.payload.data.get("mode") == "execute"]
        errors = {"arm": s.arm_errors, "hand": s.hand_errors}
        for m in read(topics.DEVICE_EVENT):
            d = m.payload.data
            if d.get("event") == "error" and d.get("device") in errors:
                errors[d["device"]].append(d.get("message", ""))
        devices = reader.metadata.get("devices", {})
    counts = {name: json.loads(v) for name, v in devices.items()}
    s.arm_refused = counts.get("arm", {}).get("refused_commands", 0)
    s.hand_refused = counts.get("hand", {}).get("refused_commands", 0)
    s.read_misses = counts.get("hand", {}).get("read_misses", 0)
    s.hand_reads = counts.get("hand", {}).get("received", 0) + s.read_misses
    s.hand_commands = sum(1 for w in wired if w.data["kind"] == "hand" and w.data["sent"])
    for w in wired:  # (/command/wire: stamped when the write began)
        s.write_ms.setdefault(w.data["kind"], []).append((w.stamp_ns - w.data["t_ns"]) / 1e6)
    s.arm_commands = len(commands)
    by_t = {c.stamp_ns: np.asarray(c.positions, float) for c in commands}
    writes = [(w.stamp_ns, by_t[w.data["t_ns"]]) for w in wired if w.data["kind"] == "arm" and w.data["t_ns"] in by_t]
    s.roundtrip_ms = roundtrips_ms(writes, states, 1e-5)

    taken = [a for a in arm["arrivals"] if a[2]]
    if len(taken) != len(commands) or len(arm["arrivals"]) != len(taken):
        s.notes.append(f"{len(commands)} arm commands recorded, {len(arm['arrivals'])} arrived ({len(taken)} taken)")
    n = min(len(taken), len(commands))
    s.matched = len(taken) == len(commands) == len(arm["arrivals"]) and all(
        np.allclose(np.asarray(taken[i][3]), np.asarray(commands[i].positions, float), atol=1e-5) for i in range(n))
    if n < 2:
        return s
    by_stamp = {t: d for t, d in ticks}
    stamps = np.array([c.stamp_ns for c in commands[:n]], dtype=np.int64)
    due = stamps  # the sender's schedule: each command is stamped with its tick's instant on the grid
    active = np.array([bool(by_stamp.get(t, {}).get("active", True)) for t in stamps.tolist()])
    arrived = np.array([a[0] for a in taken[:n]], dtype=np.int64) + offset_ns
    s.late_ms = ((arrived - due) / 1e6).tolist()
    same_run = active[:-1].copy()  # a command after an inactive tick starts a new run
    starts = np.searchsorted(stamps, np.asarray(engages, dtype=np.int64))
    starts = starts[(starts > 0) & (starts < n)]
    same_run[starts - 1] = False  # so does the first after an engage
    s.gaps_ms = (np.diff(arrived)[same_run] / 1e6).tolist()
    s.engaged_s = float(np.diff(stamps)[same_run].sum() / 1e9)
    s.per_cycle_max = max(Counter(a[1] for a in taken).values())
    return s


def roundtrips_ms(sends, seen, atol: float) -> list[float]:
    """For every command sent at t (ns), the time until a state sample (ns, positions) showed it (float32 on
    the wire: `atol`)."""
    out, k = [], 0
    for t, q in sends:
        while k < len(seen) and seen[k][0] < t:
            k += 1
        for j in range(k, min(k + 20, len(seen))):
            if np.allclose(np.asarray(seen[j][1], float), q, atol=atol):
                out.append((seen[j][0] - t) / 1e6)
                break
    return out


def run_sessions(count: int, seconds: float, engage_after: float, busy: int) -> list[WireSession]:
    from bench import common

    folder = Path(tempfile.mkdtemp(prefix="wire-"))
    sessions = []
    with common.Load(busy):
        for k in range(count):
            s = run_session(folder, k, seconds, engage_after, preview=((80, 24), (120, 45))[k % 2])
            sessions.append(s)
            print(f"wire session {k}: rc {s.returncode}, arm {s.arm_commands} commands, gap max "
                  f"{max(s.gaps_ms, default=float('nan')):.1f} ms, late p99 "
                  f"{np.percentile(s.late_ms, 99) if s.late_ms else float('nan'):.2f} ms, per cycle {s.per_cycle_max}, "
                  f"speed/accel/jerk ratio max {np.max(s.ratios, axis=0).round(3).tolist() if s.ratios else []}, "
                  f"faults {s.box_faults or 0}, arm errors {s.arm_errors[:1]}, arm refused {s.arm_refused}, "
                  f"matched {s.matched}, hand errors {s.hand_errors[:1]} {'; '.join(s.notes)}",
                  file=__import__("sys").stderr, flush=True)
    return sessions


def figures(sessions: list[WireSession]) -> dict:
    gaps = [g for s in sessions for g in s.gaps_ms]
    late = [x for s in sessions for x in s.late_ms]
    ratios = np.array([r for s in sessions for r in s.ratios] or [(np.nan,) * 3])
    reads = sum(s.hand_reads for s in sessions)
    engaged = sum(s.engaged_s for s in sessions)
    writes = {kind: [w for s in sessions for w in s.write_ms.get(kind, [])] for kind in ("arm", "hand")}

    def rate(count: int) -> float:  # per engaged second
        return round(count / engaged, 1) if engaged else float("nan")

    def p(values, q):
        return round(float(np.percentile(values, q)), 2) if values else float("nan")

    trips = [r for s in sessions for r in s.roundtrip_ms]
    return {
        "wire_sessions": len(sessions),
        "loaded_xarm_command_rate_hz": rate(sum(s.arm_commands for s in sessions)),
        "loaded_sdk_roundtrip_ms_p99": p(trips, 99),
        "wire_arrival_gap_ms_max": round(max(gaps), 2) if gaps else float("nan"),
        "wire_arrival_gap_ms_p99": p(gaps, 99),
        "wire_arrival_late_ms_p99": p(late, 99),
        "wire_arrival_late_ms_max": round(max(late), 2) if late else float("nan"),
        "wire_targets_per_cycle_max": max((s.per_cycle_max for s in sessions), default=0),
        "wire_speed_ratio_max": round(float(np.nanmax(ratios[:, 0])), 3),
        "wire_accel_ratio_max": round(float(np.nanmax(ratios[:, 1])), 3),
        "wire_jerk_ratio_max": round(float(np.nanmax(ratios[:, 2])), 3),
        "wire_write_after_tick_ms_p99": p(writes["arm"], 99),
        "leap_write_after_tick_ms_p99": p(writes["hand"], 99),
        "emulator_faults": sum(len(s.box_faults) for s in sessions),
        "loaded_xarm_session_ok": all(s.xarm_ok for s in sessions),
        "loaded_leap_session_ok": all(s.leap_ok for s in sessions),
        "loaded_leap_command_rate_hz": rate(sum(s.goal_writes for s in sessions)),
        "loaded_leap_read_miss_frac": round(sum(s.read_misses for s in sessions) / reads, 4) if reads else float("nan"),
        "loaded_leap_faults": sum(len(s.hand_errors) for s in sessions),
    }
