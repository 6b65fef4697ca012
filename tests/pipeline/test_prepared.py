"""Glove samples prepared in a batch ahead of the sequential pass (what eval does) give the pipeline the
same bits as preparing each one inside its step (what the live loop does)."""

from dataclasses import replace

import numpy as np
import pytest

from teleprev.assembly import build_driver, build_pipeline
from teleprev.human.smplx import HAND_POSE_NAMES, JOINT_FRAMES, hand_pose_from_angles
from teleprev.messages import JointSample, Logged
from teleprev.pipeline.driver import InputTopics
from teleprev.rig import load_rig
from teleprev.topics import FORMAT_VERSION
from teleprev.transforms import axis_angle_to_matrix, matrix_to_axis_angle
from tests.helpers.pipeline_inputs import ARM_HOME, RATE_HZ, wrist_sample


@pytest.fixture(scope="module", params=[FORMAT_VERSION, 2], ids=["compiled", "numpy"])
def session_format(request):
    # the compiled hot path (the current format's) and the numpy arithmetic that formats 1 and 2 re-run with
    return request.param


@pytest.fixture(scope="module")
def pipeline(session_format):
    # the default rig: LEAP Hand, shipped CPN/CCN, motion limits
    return build_pipeline(load_rig(), session_format=session_format)


def _twisted(pose: np.ndarray, twist: float) -> np.ndarray:
    """Every finger segment turned about its own bone, as an IMU glove reports it."""
    c, s = np.cos(twist), np.sin(twist)
    rx = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    return np.array([matrix_to_axis_angle(axis_angle_to_matrix(p) @ b @ rx @ b.T) for p, b in zip(pose, JOINT_FRAMES)])


def _gloves(n: int, rng) -> list[JointSample]:
    """Hand poses free and colliding, twisted and not, and unusable ones (NaN, missing names, out of range)."""
    out = []
    for k in range(n):
        pose = hand_pose_from_angles(rng.uniform(-0.2, 1.8, 15), rng.uniform(-0.4, 0.4, 15))
        if k % 5 == 1:
            pose = _twisted(pose, 0.6)
        values, names = pose.ravel(), HAND_POSE_NAMES
        if k % 17 == 3:
            values = values.copy()
            values[7] = np.nan
        if k % 19 == 4:
            values = values * 3.0
        if k % 23 == 5:
            names, values = names[:-3], values[:-3]
        out.append(JointSample(k, names, values))
    return out


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return np.array_equal(a, b) and (not isinstance(a, np.ndarray) or a.dtype == b.dtype)


def test_a_batch_prepares_each_sample_as_it_would_be_prepared_alone(pipeline, rng):
    gloves = _gloves(120, rng)
    batch = pipeline.prepare_hands(gloves)
    flags = {h.flag for h in batch}
    assert flags == {"", "glove_invalid", "glove_out_of_range"}
    for glove, h in zip(gloves, batch):
        alone = pipeline.prepare_hands([glove])[0]
        assert h.flag == alone.flag
        assert _same(h.flexion, alone.flexion) and _same(h.abduction, alone.abduction)
        if h.effector is not None:
            a, b = h.effector, alone.effector
            assert _same(a.q, b.q) and _same(a.q0, b.q0)
            assert a.report.pairs == b.report.pairs and np.array_equal(a.report.labels, b.report.labels)
    colliding = [h.effector.report.colliding for h in batch if h.effector is not None]
    assert any(colliding) and not all(colliding)


def test_the_corrector_answers_a_batch_as_it_answers_each_input(pipeline, rng):
    """Corrections done ahead (CCN per input, CPN scores batched, decided singly near the threshold)
    equal the ones `correct` computes for the input alone."""
    corrector = pipeline.effector.corrector
    q = corrector.model.sample_uniform(300, rng)
    prepared = corrector.prepare(q)
    answered = 0
    for x, p in zip(q, prepared):
        alone = corrector.correct(x)
        got = corrector.correct(x, None, p)
        answered += p.answer is not None
        assert got.action == alone.action and got.colliding_links == alone.colliding_links
        assert np.array_equal(got.q, alone.q) and got.deviation == alone.deviation
    assert answered > 100


def test_a_driver_fed_prepared_samples_computes_the_same_session(pipeline, session_format, rng):
    """A session's worth of messages, stepped with and without preparation ahead: every output the same."""
    topics = InputTopics.for_devices("glove", "suit", "arm", "hand")
    gloves = _gloves(240, rng)
    messages = []
    for k, glove in enumerate(gloves):
        t = int(k * 1e9 / RATE_HZ) + 1
        if k % 2 == 0:
            messages.append(Logged(topics.wrist, t, wrist_sample(t, k)))
        messages.append(Logged(topics.arm, t, JointSample(t, pipeline.arm_names, ARM_HOME.copy())))
        messages.append(Logged(topics.effector, t, JointSample(t, pipeline.effector_names, np.zeros(16))))
        messages.append(Logged(topics.hand, t, replace(glove, stamp_ns=t)))

    def run(prepare: bool):
        driver = build_driver(pipeline, topics, session_format)
        prepared = driver.prepare(messages) if prepare else [None] * len(messages)
        out = []
        for k, (msg, hand_input) in enumerate(zip(messages, prepared)):
            if k == 40:
                assert driver.request_mode("execute", msg.log_time_ns) == ""
            out.append(driver.feed(msg, hand_input).logged)
        return out

    live, ahead = run(False), run(True)
    assert sum(len(o) for o in live) > 500
    for a, b in zip(live, ahead):
        assert [t for t, _ in a] == [t for t, _ in b]
        for (_, x), (_, y) in zip(a, b):
            if isinstance(x, JointSample):
                assert np.array_equal(x.positions, y.positions)
            else:
                assert x.data == y.data


def test_one_input_answered_in_one_kernel_call_as_step_by_step(pipeline, rng):
    """The live step's single input (the check, the CCN step and its checks in one call,
    teleprev/kernels/correction.py) gets the answer `correct` computes from the exact check alone: the
    same action, links, bits and deviation, free inputs, shortened and full proposals alike."""
    from teleprev.noncollision.corrector import Prepared

    corrector = pipeline.effector.corrector
    q = corrector.model.sample_uniform(400, rng)
    q[::7] *= 1.3  # some beyond the limits: clipped first
    answered, actions = 0, set()
    for x in q:
        fused = corrector.prepare(x[None])[0]
        q0 = corrector.model.clip(x)
        stepwise = corrector.correct(x, None, Prepared(x, q0, corrector.checker.check(q0)))
        got = corrector.correct(x, None, fused)
        answered += fused.answer is not None
        actions.add(got.action)
        report = corrector.checker.check(q0)
        assert fused.report.pairs == report.pairs and np.array_equal(fused.report.labels, report.labels)
        assert got.action == stepwise.action and got.colliding_links == stepwise.colliding_links
        assert np.array_equal(got.q, stepwise.q) and got.deviation == stepwise.deviation
    if corrector._one is not None:  # the compiled formats: most inputs answered by the one call
        assert answered > 100 and {"untouched", "ccn", "fallback"} <= actions
        # a strided row is answered alike, by the kernel already loaded (no compile inside a live step)
        from teleprev.kernels.correction import correct_one

        loaded = len(correct_one.signatures)
        strided = np.zeros((1, 2 * q.shape[1]))
        strided[:, ::2] = q[:1]
        got = corrector.correct(q[0], None, corrector.prepare(strided[:, ::2])[0])
        assert np.array_equal(got.q, corrector.correct(q[0]).q) and len(correct_one.signatures) == loaded
    else:
        assert answered == 0
