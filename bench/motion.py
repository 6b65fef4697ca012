"""Motion figures: do the commands keep to what a real arm and hand can follow, and what does it cost?

    python bench/motion.py [--json] [--quick]

Records sim sessions of all five tasks through the real recording path (default LEAP rig: sim arm in
servo mode, sim hand), each engaged after 2 s and switched back to preview 2 s before its end (so the
controlled stop is in it), plus one session whose glove and suit are played back from recorded data
(tests/fixtures/sim_v1.mcap through the replay.* plugins). Then `teleprev audit` measures every
command stream (divided differences on the command stamps; the sim hand's measured state too):

    arm_accel_max_ratio, arm_jerk_max_ratio, hand_accel_max_ratio   max over sessions, measured / limit
    hand_swept_colliding, hand_state_colliding                      command segments / state samples
    tracking_lag_ms_p50    the shift that best lines the arm command up with the arm target, while
                           executing past the engage ramp (median over sessions)
    trajectory_us_p50      the arm generator's cost per step (ruckig and the arithmetic around it: ArmGenerator.plan
                           and follow, or stop), timed while re-running a session
    stop_distance_rad_max  the longest controlled stop: joint travel from the last command before a
                           stop began (preview, stale input, a quiet trigger) to rest
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


def tracking_lag_ms(path: Path) -> float | None:
    """The time shift (ms) that best lines the arm commands up with the arm targets, past the engage ramp."""
    import numpy as np

    from teleprev import topics
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        steady = {m.payload.stamp_ns for m in reader.messages([topics.STEP_REPORT])
                  if m.payload.data.get("mode") == "execute" and not ({"engaging", "arm_stopping"} & set(m.payload.data.get("flags", [])))}
        tt, target = stream(reader, topics.ARM_TARGET)
        tc, command = stream(reader, topics.COMMAND_ARM)
    keep = np.array([t in steady for t in tc.tolist()], dtype=bool)
    if keep.sum() < 50 or len(tt) < 50:
        return None
    tc, command = tc[keep], command[keep]
    t0 = tt[0]
    target_s, command_s = (tt - t0) / 1e9, (tc - t0) / 1e9
    best, best_err = 0.0, np.inf
    for lag_ms in np.arange(0.0, 200.0, 0.5):
        shifted = np.stack([np.interp(command_s - lag_ms / 1000, target_s, target[:, j]) for j in range(target.shape[1])], axis=1)
        err = float(np.mean(np.abs(command - shifted)))
        if err < best_err:
            best, best_err = float(lag_ms), err
    return best


def stop_distances(path: Path) -> list[float]:
    """Joint travel of every controlled stop: from the last command before the stop began to rest."""
    import numpy as np

    from teleprev import topics
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        flags = {m.payload.stamp_ns: set(m.payload.data.get("flags", [])) for m in reader.messages([topics.STEP_REPORT])}
        tc, command = stream(reader, topics.COMMAND_ARM)
    stopping = np.array([bool({"stopping", "arm_stopping", "idle_stop"} & flags.get(t, set())) for t in tc.tolist()])
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
    seconds = 8.0 if args.quick else 14.0

    from teleprev.evaluation.audit import audit_session

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        sessions = [record(tmp / f"{task}.mcap", None, task, seconds) for task in TASKS]
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
