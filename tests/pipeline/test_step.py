"""The pure pipeline step: preview sends nothing, execute ramps and follows within limits, bad input holds.

These run the speed-capped pipeline that sessions of format 1 were recorded with (session_format=1);
tests/pipeline/test_motion.py covers the acceleration and jerk limits of newer sessions."""

import dataclasses

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.pipeline.config import PipelineConfig
from teleprev.pipeline.older_formats import StepCommandsState
from teleprev.rig import Rig, RigSection
from tests.helpers.pipeline_inputs import inputs


def _rig(end_effector: str, robot: str, **pipeline) -> Rig:
    return Rig(None, RigSection(robot=robot, end_effector=end_effector), PipelineConfig(**pipeline), {})


@pytest.fixture(scope="module")
def gripper_pipeline():
    return build_pipeline(_rig("parallel_gripper", "xarm6_parallel_gripper"), session_format=1)


def _run(p, steps, engage_at=None, state=None, make=None):
    make = make or (lambda k: inputs(k, p.arm_names, p.effector_names, [0.05]))
    state = state or StepCommandsState()
    results = []
    for k in range(steps):
        i = make(k)
        if k == engage_at:
            state, refused = p.set_mode(state, "execute", i)
            assert refused == ""
        r = p.step(state, i)
        state = r.state
        results.append((i, r))
    return state, results


def test_preview_computes_targets_but_commands_nothing(gripper_pipeline):
    _, results = _run(gripper_pipeline, 300)
    assert all(r.arm_command is None and r.effector_command is None for _, r in results)
    assert sum(r.arm_target is not None for _, r in results) == 300
    assert all(r.report["mode"] == "preview" for _, r in results)


def test_execute_ramps_from_the_measured_pose_then_follows_within_speed_caps(gripper_pipeline):
    p = gripper_pipeline
    _, results = _run(p, 600, engage_at=100)
    commands = [(i.t_ns, r.arm_command, r.effector_command) for i, r in results if r.arm_command is not None]
    assert len(commands) == 500
    first_t, first_arm, _ = commands[0]
    # the first command is one capped step away from the measured home pose
    assert (
        np.max(np.abs(first_arm - results[100][0].arm.positions))
        <= p.arm_guard.speed.max() * 0.5 * p.arm_guard.max_dt + 1e-12
    )
    caps_arm, caps_eff = p.arm_guard.speed, p.effector.guard.speed
    for (t0, a0, e0), (t1, a1, e1) in zip(commands, commands[1:]):
        dt = (t1 - t0) / 1e9
        assert np.all(np.abs(a1 - a0) <= caps_arm * dt + 1e-12)
        assert np.all(np.abs(e1 - e0) <= caps_eff * dt + 1e-12)
        assert np.all(a1 >= p.arm_guard.lower) and np.all(a1 <= p.arm_guard.upper)
    # the ramp ends, after which commands track the targets
    engaged = [
        k for k, (_, r) in enumerate(results) if r.arm_command is not None and "engaging" not in r.report["flags"]
    ]
    assert engaged, "the engage ramp never finished"
    k = engaged[len(engaged) // 2]
    assert np.allclose(results[k][1].arm_command, results[k][1].arm_target, atol=1e-3)


def test_engage_is_refused_before_anything_was_previewed(gripper_pipeline):
    p = gripper_pipeline
    state, refused = p.set_mode(StepCommandsState(), "execute", inputs(0, p.arm_names, p.effector_names, [0.05]))
    assert refused and state.mode == "preview"


def test_switching_back_to_preview_stops_commands_and_reanchors(gripper_pipeline):
    p = gripper_pipeline
    state, _ = _run(p, 200, engage_at=50)
    state, refused = p.set_mode(state, "preview", inputs(200, p.arm_names, p.effector_names, [0.05]))
    assert refused == "" and state.anchor is None
    r = p.step(state, inputs(201, p.arm_names, p.effector_names, [0.05]))
    assert r.arm_command is None and r.state.anchor is not None


@pytest.mark.parametrize(
    "corrupt, flag, holds",
    [
        (
            lambda i: dataclasses.replace(i, hand=dataclasses.replace(i.hand, positions=np.full(45, np.nan))),
            "glove_invalid",
            "effector",
        ),
        (
            lambda i: dataclasses.replace(i, hand=dataclasses.replace(i.hand, stamp_ns=i.t_ns - 10**9)),
            "glove_stale",
            "effector",
        ),
        (
            lambda i: dataclasses.replace(i, hand=dataclasses.replace(i.hand, positions=i.hand.positions * 20)),
            "glove_out_of_range",
            "effector",
        ),
        (
            lambda i: dataclasses.replace(i, wrist=dataclasses.replace(i.wrist, position=np.array([np.nan, 0, 1]))),
            "suit_invalid",
            "arm",
        ),
        (
            lambda i: dataclasses.replace(i, wrist=dataclasses.replace(i.wrist, stamp_ns=i.t_ns - 10**9)),
            "suit_stale",
            "arm",
        ),
        (
            lambda i: dataclasses.replace(i, wrist=dataclasses.replace(i.wrist, position=np.array([40.0, 0, 1]))),
            "suit_out_of_range",
            "arm",
        ),
    ],
)
def test_bad_input_holds_the_last_valid_command_and_is_flagged(gripper_pipeline, corrupt, flag, holds):
    p = gripper_pipeline
    state, _ = _run(p, 200, engage_at=20)
    last_arm, last_eff = state.arm_cmd.copy(), state.effector_cmd.copy()
    r = p.step(state, corrupt(inputs(200, p.arm_names, p.effector_names, [0.05])))
    assert flag in r.report["flags"]
    if holds == "effector":
        assert r.effector_command is None and np.array_equal(r.state.effector_cmd, last_eff)
        assert r.arm_command is not None
    else:
        assert r.arm_command is None and np.array_equal(r.state.arm_cmd, last_arm)
        assert r.effector_command is not None
    # and the next good input carries on from the held command
    r2 = p.step(r.state, inputs(201, p.arm_names, p.effector_names, [0.05]))
    assert r2.arm_command is not None and r2.effector_command is not None


def test_the_step_is_deterministic(gripper_pipeline):
    p = gripper_pipeline
    _, a = _run(p, 300, engage_at=40)
    _, b = _run(p, 300, engage_at=40)
    for (_, ra), (_, rb) in zip(a, b):
        for field in ("arm_target", "arm_command", "effector_command"):
            x, y = getattr(ra, field), getattr(rb, field)
            assert (x is None and y is None) or np.array_equal(x, y)


def test_vacuum_switches_with_hysteresis_in_the_pipeline():
    p = build_pipeline(_rig("vacuum", "xarm6_vacuum"), session_format=1)
    flex = [0.0, 0.5, 1.0, 0.8, 0.7, 0.5, 0.8, 1.0]
    state, on = StepCommandsState(), []
    for k, f in enumerate(flex):
        r = p.step(state, inputs(k, p.arm_names, p.effector_names, [0.0], flexion=np.full(15, f)))
        state = r.state
        on.append(r.corrected[0])
    assert on == [0, 0, 1, 1, 1, 0, 0, 1]


def test_measured_rows_are_measured_one_by_one(gripper_pipeline, rng):
    """Eval's measured states at once: the samples measured() gives values for, in order, the same values
    (names in another order, a joint missing, NaN and inf rows among them)."""
    from teleprev.messages import JointSample

    p = gripper_pipeline
    names = p.arm_names
    plain = [JointSample(1000 + k, names, rng.standard_normal(len(names))) for k in range(50)]
    for k in (3, 17):
        plain[k].positions[k % len(names)] = (np.nan, np.inf)[k % 2]
    shuffled = tuple(reversed(names))
    odd = [
        JointSample(2000, shuffled, rng.standard_normal(len(names))),
        JointSample(2001, names[:-1], np.zeros(len(names) - 1)),
    ]
    for samples in (plain, plain[:1], [], plain[:20] + odd + plain[20:]):
        stamps, rows = p.measured_rows(samples, names)
        expected = [(s.stamp_ns, q) for s in samples if (q := p.measured(s, names)) is not None]
        assert stamps == [t for t, _ in expected]
        assert rows.shape == (len(expected), len(names))
        assert rows.tobytes() == b"".join(q.tobytes() for _, q in expected)
    assert len(p.measured_rows(plain, names)[0]) == 48
