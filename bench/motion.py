"""Motion figures: do the commands keep to what a real arm and hand can follow, and what does it cost?

    python bench/motion.py [--json] [--quick]

Records sim sessions of all five tasks through the real recording path (default LEAP rig: sim arm in
servo mode, sim hand), each engaged after 2 s and switched back to preview 2 s before its end (so the
controlled stop is in it), plus one session whose glove and suit are played back from recorded data
(tests/fixtures/sim_v1.mcap through the replay.* plugins); --quick: sessions of 6 s, of the first task and
the played-back one. Then `teleprev audit` measures every
command stream (divided differences on the command stamps; the sim hand's measured state too):

    arm_accel_max_ratio, arm_jerk_max_ratio, hand_accel_max_ratio   max over sessions, measured / limit
    hand_swept_colliding, hand_state_colliding                      command segments / state samples
    tracking_lag_ms_p50    how far the arm command lags the arm target: the shift that best lines them up,
                           over the commands of steady ticks (not engaging or braking; the tick's flags on
                           /command/tick), median over sessions
    trajectory_us_p50      the arm generator's cost per step (ruckig and the arithmetic around it: ArmGenerator.plan
                           and follow, or stop), timed while re-running a session
    stop_distance_rad_max  the longest controlled stop: joint travel from the last command before a
                           stop began (a switch to preview, a stale target) to rest

JSON keys:
    arm_accel_max_ratio      float
    arm_jerk_max_ratio       float
    hand_accel_max_ratio     float
    hand_swept_colliding     int
    hand_state_colliding     int
    tracking_lag_ms_p50      float
    trajectory_us_p50        float
    stop_distance_rad_max    float
    arm_speed_max_ratio      float
    hand_speed_max_ratio     float
    sessions                 int
    arm_commands             int
    hand_commands            int
    controlled_stops         int
    trajectory_us_p99        float
    audits_passed            int
    hand_commands_colliding  int
    commands_outside_limits  int
"""

from __future__ import annotations

import re
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402

TASKS = ("pick_place", "hang", "pour", "box_rotation", "cup_stack")
ROOT = Path(__file__).resolve().parents[1]


def record(out: Path, rig: Path | None, task: str, seconds: float) -> Path:
    from teleprev.live.record.session import LiveSession, RecordOptions

    rec = LiveSession(RecordOptions(out=out, rig=rig, task=task))
    rec.start()
    try:
        rec.loop.start_episode(task)
        time.sleep(2.0)
        rec.loop.engage("bench")
        time.sleep(seconds - 4.0)
        rec.loop.to_preview("bench")
        time.sleep(2.0)
        rec.loop.stop_episode()
    finally:
        rec.stop()
    return out


def replay_rig(tmp: Path) -> Path:
    """The default sim rig with glove and suit played back from a recorded session."""
    text = (ROOT / "rigs" / "sim.toml").read_text()
    head, _, _ = text.partition("[devices.glove]")
    session = ROOT / "tests" / "fixtures" / "sim_v1.mcap"
    arm_hand = text[text.index("[devices.arm]"):]
    rig = head + f"""[devices.glove]
plugin = "replay.glove"
session = "{session}"

[devices.suit]
plugin = "replay.suit"
session = "{session}"

""" + arm_hand
    rig = re.sub(r"(?ms)^\[frames\.cam_front\].*?(?=^\[)", "", rig)  # the played-back rig has no camera
    path = tmp / "replay.toml"
    path.write_text(rig)
    return path


def stream(reader, topic):
    import numpy as np

    msgs = [m.payload for m in reader.messages([topic])] if topic in reader.topics else []
    return np.array([m.stamp_ns for m in msgs], dtype=np.int64), np.array([m.positions for m in msgs])


# the sender's reasons (teleprev/pipeline/planner.py) for commands that do not simply follow the target
UNSTEADY = {"engaging", "stopping", "arm_stopping", "targets_stale", "commands_resumed", "arm_limit_braking",
            "arm_limit_held", "halt"}
STOPPING = {"stopping", "arm_stopping"}  # braking to rest: a switch to preview, or a target gone stale


def command_flags(reader, stamps) -> list[set[str]]:
    """The flags of the sender's tick (/command/tick, stamped as its commands) behind each command stamp."""
    from teleprev import topics

    flags = {m.payload.stamp_ns: set(m.payload.data.get("flags", [])) for m in reader.messages([topics.COMMAND_TICK])}
    return [flags.get(t, {"no_tick"}) for t in stamps.tolist()]


def tracking_lag_ms(path: Path) -> float | None:
    """The time shift (ms) that best lines the arm commands up with the arm targets: the mean absolute joint
    error between each command and the target interpolated that much earlier, least over shifts of -100
    to 300 ms in 0.5 ms steps (negative: the command leads, as the sender's extrapolation of the target to
    the tick's instant can make it), over the commands of steady ticks (following, not engaging or
    braking). None where fewer than 50 commands are steady, or where the best shift is at either end of the
    range (the lag is not in it)."""
    import numpy as np

    from teleprev import topics
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        tt, target = stream(reader, topics.ARM_TARGET)
        tc, command = stream(reader, topics.COMMAND_ARM)
        flags = command_flags(reader, tc)
    if len(tt) < 50:
        return None
    keep = np.array([not (f & UNSTEADY) for f in flags], dtype=bool) & (tc >= tt[0]) & (tc <= tt[-1])
    if keep.sum() < 50:
        return None
    tc, command = tc[keep], command[keep]
    target_s, command_s = (tt - tt[0]) / 1e9, (tc - tt[0]) / 1e9
    lags_ms = np.arange(-100.0, 300.0, 0.5)
    errors = [float(np.mean(np.abs(command - np.stack([np.interp(command_s - lag / 1000, target_s, target[:, j])
                                                       for j in range(target.shape[1])], axis=1))))
              for lag in lags_ms]
    best = int(np.argmin(errors))
    return None if best in (0, len(lags_ms) - 1) else float(lags_ms[best])


def stop_distances(path: Path) -> list[float]:
    """Joint travel of every controlled stop: from the last command before the stop began to rest."""
    import numpy as np

    from teleprev import topics
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        tc, command = stream(reader, topics.COMMAND_ARM)
        stopping = np.array([bool(STOPPING & f) for f in command_flags(reader, tc)])
    out = []
    k = 0
    while k < len(tc):
        if stopping[k] and k > 0:
            start = k - 1
            while k < len(tc) and stopping[k]:
                k += 1
            out.append(float(np.abs(command[k - 1] - command[start]).max()))
        k += 1
    return out


def generator_cost_us(path: Path) -> list[float]:
    """Per-step cost of the arm generator (ArmGenerator.plan and follow, or stop), timed during a re-run of
    a session."""
    from teleprev.evaluation.reproduce import rerun_session
    from teleprev.pipeline import trajectory

    times: list[float] = []
    planned = [0.0]  # a step's plan, to count with its follow
    originals = {name: getattr(trajectory.ArmGenerator, name) for name in ("plan", "follow", "stop")}

    def timed(name, fn):
        def call(self, *args, **kwargs):
            t = time.perf_counter_ns()
            out = fn(self, *args, **kwargs)
            us = (time.perf_counter_ns() - t) / 1000.0
            if name == "plan":
                planned[0] = us
            else:
                times.append(us + planned[0])
                planned[0] = 0.0
            return out
        return call

    for name, fn in originals.items():
        setattr(trajectory.ArmGenerator, name, timed(name, fn))
    try:
        rerun_session(path)
    finally:
        for name, fn in originals.items():
            setattr(trajectory.ArmGenerator, name, fn)
    return times


def main() -> None:
    p = common.parser(__doc__)
    args = p.parse_args()
    seconds = 6.0 if args.quick else 14.0
    tasks = TASKS[:1] if args.quick else TASKS

    from teleprev.evaluation.audit import audit_session

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sessions = [record(tmp / f"{task}.mcap", None, task, seconds) for task in tasks]
        sessions.append(record(tmp / "replayed.mcap", replay_rig(tmp), "pick_place", seconds))
        audits = [audit_session(s) for s in sessions]
        lags = [lag for lag in (tracking_lag_ms(s) for s in sessions) if lag is not None]
        stops = [d for s in sessions for d in stop_distances(s)]
        cost = generator_cost_us(sessions[0])

    def ratio(side: int, key: str) -> float:
        return max(a.streams[side].ratios.get(key, 0.0) for a in audits)

    figures = {
        "arm_accel_max_ratio": ratio(0, "accel"),
        "arm_jerk_max_ratio": ratio(0, "jerk"),
        "hand_accel_max_ratio": ratio(1, "accel"),
        "hand_swept_colliding": sum(a.streams[1].swept_colliding or 0 for a in audits),
        "hand_state_colliding": sum(a.hand_state_colliding or 0 for a in audits),
        "tracking_lag_ms_p50": common.percentile(lags, 50) if lags else float("nan"),
        "trajectory_us_p50": common.percentile(cost, 50) if cost else float("nan"),
        "stop_distance_rad_max": max(stops) if stops else 0.0,
        "arm_speed_max_ratio": ratio(0, "speed"),
        "hand_speed_max_ratio": ratio(1, "speed"),
        "sessions": len(sessions),
        "arm_commands": sum(a.streams[0].commands for a in audits),
        "hand_commands": sum(a.streams[1].commands for a in audits),
        "controlled_stops": len(stops),
        "trajectory_us_p99": common.percentile(cost, 99) if cost else float("nan"),
        "audits_passed": sum(a.ok for a in audits),
        "hand_commands_colliding": sum(a.streams[1].colliding or 0 for a in audits),
        "commands_outside_limits": sum(st.position_outside for a in audits for st in a.streams),
    }
    for a in audits:
        if not a.ok:
            print(f"audit failed: {Path(a.session).name}: " + "; ".join(
                f"{st.topic}: {v}" for st in a.streams for v in st.violations), file=sys.stderr)
    targets = {"arm_accel_max_ratio": "<= 1.05", "arm_jerk_max_ratio": "<= 1.05", "hand_accel_max_ratio": "<= 1.05",
               "hand_swept_colliding": "0", "hand_state_colliding": "0", "tracking_lag_ms_p50": "goal <= 40",
               "trajectory_us_p50": "<= 30"}
    common.report("bench/motion.py: commands a real arm and hand can follow", figures, targets, args.json)


if __name__ == "__main__":
    main()
