"""Commands a real arm can follow: jerk-limited arm commands (ruckig), an acceleration-capped hand, and
controlled stops (stale input, a quiet trigger device, a switch to preview), all measured the way the
audit measures them: divided differences on the command stamps."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.errors import ConfigError
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.older_formats import StepCommandsState
from teleprev.rig import Rig, RigSection, load_rig_text
from teleprev.robot.limits import arm_limits, effector_limits
from tests.helpers.pipeline_inputs import inputs

ARM = arm_limits("xarm6")
GRIPPER = effector_limits("parallel_gripper")


def _rig(end_effector="parallel_gripper", robot="xarm6_parallel_gripper", **pipeline) -> Rig:
    return Rig(None, RigSection(robot=robot, end_effector=end_effector), PipelineConfig(**pipeline), {})


@pytest.fixture(scope="module")
def pipeline():
    return build_pipeline(_rig(), session_format=3)  # format 3: commands made at each step (Motion)


def derivatives(t_ns, q):
    """Velocity, acceleration and jerk by divided differences on the stamps (what the audit measures)."""
    t_ns = np.asarray(t_ns, dtype=np.int64)
    t = (t_ns - t_ns[0]) / 1e9  # integer nanoseconds first: epoch seconds in float64 lose ~1e-7 s
    q = np.asarray(q, dtype=float)
    v = np.diff(q, axis=0) / np.diff(t)[:, None]
    f2 = np.diff(v, axis=0) / (t[2:] - t[:-2])[:, None]
    f3 = np.diff(f2, axis=0) / (t[3:] - t[:-3])[:, None]
    return v, 2.0 * f2, 6.0 * f3  # k! times the k-th divided difference: a k-th derivative somewhere between


def run(p, steps, engage_at=None, state=None, make=None, mode_at=None):
    make = make or (lambda k: inputs(k, p.arm_names, p.effector_names, [0.05]))
    state = state or StepCommandsState()
    out = []
    for k in range(steps):
        i = make(k)
        if k == engage_at:
            state, refused = p.set_mode(state, "execute", i)
            assert refused == ""
        if mode_at and k in mode_at:
            state, refused = p.set_mode(state, mode_at[k], i)
            assert refused == ""
        r = p.step(state, i)
        state = r.state
        out.append((i, r))
    return state, out


def commands(results, field="arm_command"):
    rows = [(i.t_ns, getattr(r, field)) for i, r in results if getattr(r, field) is not None]
    return np.array([t for t, _ in rows]), np.array([q for _, q in rows])


def assert_within(t, q, velocity, acceleration, jerk=None, tol=1e-6):
    v, a, j = derivatives(t, q)
    assert np.abs(v).max() <= velocity * (1 + tol), np.abs(v).max()
    assert np.abs(a).max() <= acceleration * (1 + tol), np.abs(a).max()
    if jerk is not None:
        assert np.abs(j).max() <= jerk * (1 + tol), np.abs(j).max()


def test_arm_commands_stay_within_velocity_acceleration_and_jerk_and_track_the_target(pipeline):
    p = pipeline
    _, results = run(p, 900, engage_at=100)
    t, q = commands(results)
    assert len(t) == 800  # one command per step from the engage on
    # the first command barely leaves the measured pose: the arm starts from rest
    assert np.abs(q[0] - results[100][0].arm.positions).max() < 1e-5
    assert_within(t, q, 2.14, ARM.acceleration, ARM.jerk)
    _, hand = commands(results, "effector_command")
    assert_within(t, hand, 0.15, GRIPPER.acceleration)
    engaged = [
        k for k, (_, r) in enumerate(results) if r.arm_command is not None and "engaging" not in r.report["flags"]
    ]
    assert engaged and engaged[0] < 400, "the engage ramp never finished"
    err = [np.abs(results[k][1].arm_command - results[k][1].arm_target).max() for k in engaged[100:]]
    assert np.median(err) < 0.01  # tracks the moving target closely (velocity feed-forward)


def test_a_stale_suit_brakes_the_arm_to_rest_within_the_limits_then_holds(pipeline):
    p = pipeline
    stale_from = 400

    def make(k):
        i = inputs(k, p.arm_names, p.effector_names, [0.05])
        if k >= stale_from:
            i = dataclasses.replace(
                i, wrist=dataclasses.replace(i.wrist, stamp_ns=inputs(stale_from, (), (), [0.0]).t_ns - 10**9)
            )
        return i

    _, results = run(p, 600, engage_at=100, make=make)
    moving = results[stale_from - 1][1].state.motion.arm
    assert np.abs(moving.v).max() > 0.1  # it was moving when the suit went stale
    t, q = commands(results)
    assert_within(t, q, 2.14, ARM.acceleration, ARM.jerk)
    stopping = [k for k, (_, r) in enumerate(results) if "arm_stopping" in r.report["flags"]]
    assert stopping[0] == stale_from and len(stopping) > 3  # a ramp down, not a freeze
    last = stopping[-1]
    assert results[last][1].state.motion.arm.at_rest
    after = [r for _, r in results[last + 1:]]
    assert all(r.arm_command is None for r in after) and all(r.effector_command is not None for r in after)


def test_switching_to_preview_brakes_to_rest_then_sends_nothing_and_reanchors(pipeline):
    p = pipeline
    state, results = run(p, 400, engage_at=100)
    assert not state.motion.arm.at_rest
    state, refused = p.set_mode(state, "preview", results[-1][0])
    assert refused == "" and state.mode == "preview" and state.anchor is None
    _, more = run(p, 200, state=state, make=lambda k: inputs(400 + k, p.arm_names, p.effector_names, [0.05]))
    sent = [(i, r) for i, r in more if r.arm_command is not None]
    assert sent and all("stopping" in r.report["flags"] for _, r in sent)
    assert all(r.arm_command is None and r.effector_command is None for _, r in more[len(sent):])
    assert more[-1][1].state.anchor is not None and more[-1][1].state.motion is None
    t, q = commands(results + more)
    assert_within(t, q, 2.14, ARM.acceleration, ARM.jerk)
    # how far the stop went: what braking from this speed costs, no more
    stop = np.abs(q[-1] - results[-1][1].arm_command).max()
    assert 0 < stop < 0.5


def test_estop_stops_commanding_at_once(pipeline):
    p = pipeline
    state, results = run(p, 300, engage_at=100)
    state, refused = p.set_mode(state, "estop", results[-1][0])
    assert refused == "" and state.mode == "preview" and state.motion is None
    r = p.step(state, inputs(300, p.arm_names, p.effector_names, [0.05]))
    assert r.arm_command is None and r.effector_command is None


def test_idle_steps_brake_when_no_trigger_sample_comes(pipeline):
    p = pipeline
    state, results = run(p, 300, engage_at=100)
    last_t = results[-1][0].t_ns
    assert p.idle_step(state, inputs(300, p.arm_names, p.effector_names, [0.05])) is None  # not due yet
    t, q = commands(results)
    ts, qs = list(t), list(q)
    for k in range(1, 100):  # the glove went quiet: arm state samples at 100 Hz keep the clock going
        i = dataclasses.replace(
            inputs(300, p.arm_names, p.effector_names, [0.05]), t_ns=last_t + 25_000_000 + k * 10_000_000
        )
        r = p.idle_step(state, i)
        if r is None:
            break
        assert "idle_stop" in r.report["flags"]
        state = r.state
        if r.arm_command is not None:
            ts.append(i.t_ns)
            qs.append(r.arm_command)
    assert len(ts) > len(t) + 3 and state.motion.arm.at_rest
    assert_within(np.array(ts), np.array(qs), 2.14, ARM.acceleration, ARM.jerk)


def test_the_motion_step_is_deterministic(pipeline):
    p = pipeline
    _, a = run(p, 400, engage_at=40, mode_at={300: "preview"})
    _, b = run(p, 400, engage_at=40, mode_at={300: "preview"})
    for (_, ra), (_, rb) in zip(a, b):
        for field in ("arm_target", "arm_command", "effector_command"):
            x, y = getattr(ra, field), getattr(rb, field)
            assert (x is None and y is None) or np.array_equal(x, y)


def test_limits_come_from_the_rig_before_the_table():
    p = build_pipeline(_rig(arm_acceleration=4.0, arm_jerk=100.0), session_format=3)
    _, results = run(p, 500, engage_at=100)
    t, q = commands(results)
    v, a, j = derivatives(t, q)
    assert 3.0 < np.abs(a).max() <= 4.0 * (1 + 1e-6) and np.abs(j).max() <= 100.0 * (1 + 1e-6)


RIG = """
[rig]
robot = "{robot}"
end_effector = "parallel_gripper"
[pipeline]
{pipeline}
[devices.glove]
plugin = "sim.glove"
"""


@pytest.mark.parametrize("robot, pipeline, match", [
    ("xarm6_parallel_gripper", "arm_acceleration = -10.0", r"arm_acceleration must be a positive"),
    ("xarm6_parallel_gripper", "arm_jerk = 0", r"arm_jerk must be a positive"),
    ("xarm6_parallel_gripper", "arm_tcp_speed = -1.0", r"arm_tcp_speed must be a positive"),
    ("xarm6_parallel_gripper", "arm_speed = 4.0", r"looser than the URDF's velocity limit"),
])
def test_bad_limits_in_a_rig_name_the_file_and_key(robot, pipeline, match):
    with pytest.raises(ConfigError, match=match) as err:
        build_pipeline(
            load_rig_text(RIG.format(robot=robot, pipeline=pipeline), "rigs/bad.toml", Path("rigs/bad.toml"))
        )
    assert "rigs/bad.toml" in str(err.value)
    key = pipeline.split(" =")[0]
    assert key in str(err.value)


def test_a_robot_missing_from_the_table_needs_the_limits_in_the_rig(monkeypatch):
    from teleprev.robot import limits

    monkeypatch.setattr(limits, "ARMS", {})
    with pytest.raises(ConfigError, match=r"arm_acceleration"):
        build_pipeline(_rig())
    build_pipeline(_rig(arm_acceleration=5.0, arm_jerk=200.0))  # with the keys it builds


def test_after_a_stall_the_commands_start_again_from_rest_at_the_last_one(pipeline):
    p = pipeline
    state, results = run(p, 300, engage_at=100)
    assert not state.motion.arm.at_rest
    last = state.arm_cmd.copy()
    # no step for 120 ms (the process stalled): a servo-mode arm stood at the last command meanwhile
    _, more = run(p, 200, state=state, make=lambda k: inputs(315 + k, p.arm_names, p.effector_names, [0.05]))
    assert "commands_resumed" in more[0][1].report["flags"]
    t, q = commands(more)
    assert np.abs(q[0] - last).max() < 1e-4  # from rest at the last command, not 120 ms further on
    # within the limits from rest: two samples of the arm standing there first
    assert_within(
        np.r_[t[0] - 2 * 10**7, t[0] - 10**7, t], np.vstack([last, last, q]), 2.14, ARM.acceleration, ARM.jerk
    )


def test_after_a_stall_with_an_idle_step_first_the_next_command_still_starts_from_rest(pipeline):
    """The stall is met first by an idle step (an arm state sample), which finds the commands stood at
    rest and sends nothing; the next glove step must still start one short step from rest, not plan
    over the whole pause (a jump the sim arm, like the controller, faults on)."""
    p = pipeline
    state, results = run(p, 300, engage_at=100)
    last, last_t = state.arm_cmd.copy(), results[-1][0].t_ns
    idle = p.idle_step(
        state, dataclasses.replace(inputs(300, p.arm_names, p.effector_names, [0.05]), t_ns=last_t + 107_000_000)
    )
    assert idle is not None and "commands_resumed" in idle.report["flags"] and idle.arm_command is None
    _, more = run(p, 100, state=idle.state, make=lambda k: inputs(314 + k, p.arm_names, p.effector_names, [0.05]))
    t, q = commands(more)
    assert np.abs(q[0] - last).max() < 1e-4
    assert_within(
        np.r_[t[0] - 2 * 10**7, t[0] - 10**7, t], np.vstack([last, last, q]), 2.14, ARM.acceleration, ARM.jerk
    )


def test_a_stop_that_would_pass_a_joint_limit_holds_the_command_at_the_limit(pipeline):
    """Moving fast 0.05 rad short of a joint limit, the jerk-limited profile cannot stop before it and
    passes it; the command sent never leaves the limits."""
    from teleprev.pipeline.trajectory import JointMotion

    p = pipeline
    state, results = run(p, 200, engage_at=100)
    upper = p.motion.arm.upper
    q = state.arm_cmd.copy()
    q[0] = upper[0] - 0.05
    v = np.zeros_like(q)
    v[0] = 1.5  # rad/s towards the limit: a jerk-limited stop needs ~0.13 rad
    fast = dataclasses.replace(
        state, arm_cmd=q, motion=dataclasses.replace(state.motion, arm=JointMotion(q, v, np.zeros_like(q)))
    )
    s = fast.motion.arm
    for _ in range(30):
        s = p.motion.arm.stop(s, 1 / 120)
    assert s.q[0] > upper[0]  # the profile itself passes the limit
    _, more = run(p, 30, state=fast, make=lambda k: inputs(200 + k, p.arm_names, p.effector_names, [0.05]),
                  mode_at={0: "preview"})
    t, qs = commands(more)
    assert len(t) > 5 and np.all(qs <= upper + 1e-12) and np.all(qs >= p.motion.arm.lower - 1e-12)
    assert any("arm_limit_held" in r.report["flags"] for _, r in more)
