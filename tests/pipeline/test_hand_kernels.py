"""The compiled glove preparation (teleprev/kernels/glove.py) against the
numpy one it stands in for: the same flags on every input, good or broken, angles and joints within
1e-12, for the reading of formats 3 and 4 (abduction first, against formats 1 and 2's numpy pipeline) and
for format 5's (flexion first, against smplx.angles_from_hand_pose); and one sample prepared alone (the
live step) has the same bits as in a batch (eval)."""

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.human.smplx import (
    HAND_POSE_NAMES,
    TWIST_NOISE,
    angles_from_hand_pose,
    hand_pose_from_angles,
    hand_pose_from_values,
    hand_values,
)
from teleprev.kernels import glove as hand_kernels
from teleprev.messages import JointSample
from teleprev.pipeline.step import MAX_ABDUCTION, MAX_FLEXION, MAX_JOINT_ROTATION, MIN_FLEXION, HandInput
from teleprev.rig import load_rig
from tests.helpers.pipeline_inputs import twisted
from tests.helpers.sessions import RIGS

SIM_RIGS = {"leap_hand": "sim.toml", "parallel_gripper": "sim_gripper.toml", "vacuum": "sim_vacuum.toml"}


@pytest.fixture(scope="module")
def pipelines():
    """{effector: (numpy pipeline, compiled pipeline)} for each end effector's sim rig: the numpy one of
    formats 1 and 2 and the compiled one of format 4, both reading abduction first."""
    return {
        name: (
            build_pipeline(load_rig(RIGS / rig), session_format=2),
            build_pipeline(load_rig(RIGS / rig), session_format=4),
        )
        for name, rig in SIM_RIGS.items()
    }


@pytest.fixture(scope="module")
def current():
    """{effector: the current format's pipeline} (flexion first)."""
    return {name: build_pipeline(load_rig(RIGS / rig)) for name, rig in SIM_RIGS.items()}


class FlexionFirstInNumpy:
    """The current format's preparation in numpy: the same checks, smplx.angles_from_hand_pose, the
    effector's own preparation (the reference the compiled kernel must agree with)."""

    def __init__(self, pipeline):
        self.effector = pipeline.effector

    def prepare_hands(self, samples):
        return [self._one(s) for s in samples]

    def _one(self, s) -> HandInput:
        try:
            pose = hand_pose_from_values(s.names, s.positions)
        except KeyError:
            return HandInput("glove_invalid")
        if not np.isfinite(pose).all():
            return HandInput("glove_invalid")
        if np.einsum("ij,ij->i", pose, pose).max() > MAX_JOINT_ROTATION**2:
            return HandInput("glove_out_of_range")
        flexion, abduction = angles_from_hand_pose(pose)
        if flexion.max() > MAX_FLEXION or flexion.min() < MIN_FLEXION or abs(abduction).max() > MAX_ABDUCTION:
            return HandInput("glove_out_of_range")
        return HandInput("", flexion, abduction, self.effector.prepare(flexion[None], abduction[None])[0])


def _pose(rng, flexion=(-0.2, 1.8), abduction=(-0.4, 0.4)) -> np.ndarray:
    return hand_pose_from_angles(rng.uniform(*flexion, 15), rng.uniform(*abduction, 15))


def _gloves(rng) -> list[JointSample]:
    """Plausible hands (twisted or not, flexion past 90 degrees, near the bounds) and every broken kind."""
    out = []

    def add(pose, names=HAND_POSE_NAMES):
        values = np.asarray(pose, dtype=float).ravel()
        out.append(JointSample(len(out), tuple(names), values))

    for _ in range(150):
        add(_pose(rng))
    for twist in (0.6, -1.2, 1.5):
        for _ in range(20):
            add(twisted(_pose(rng), rng.choice(15, 5, replace=False), twist))
    for _ in range(20):
        add(_pose(rng, flexion=(1.6, 2.6)))  # past 90 degrees
        add(_pose(rng, flexion=(2.5, 2.69), abduction=(-1.29, 1.29)))  # near the bounds
        add(_pose(rng, flexion=(2.65, 2.75)))  # straddling MAX_FLEXION
        add(_pose(rng, flexion=(-1.3, -1.1)))  # straddling MIN_FLEXION
        add(_pose(rng, abduction=(1.25, 1.35)))  # straddling MAX_ABDUCTION
    for bad in (np.nan, np.inf, -np.inf):
        for k in (0, 17, 44):
            v = _pose(rng).ravel()
            v[k] = bad
            add(v)
    for scale in (3.0, 50.0, 1e300):  # rotations beyond MAX_JOINT_ROTATION
        add(_pose(rng) * scale)
    v = _pose(rng).ravel()
    v[3:6] = [MAX_JOINT_ROTATION, 0.0, 0.0]  # exactly at the limit: plausible
    add(v)
    v[3] = np.nextafter(MAX_JOINT_ROTATION, 4.0)
    add(v)
    add(np.zeros(45))  # the rest pose
    order = rng.permutation(45)
    for _ in range(10):  # reordered names, extra names
        v = _pose(rng).ravel()
        add(v[order], np.array(HAND_POSE_NAMES)[order])
        add(np.r_[v, 1.0], HAND_POSE_NAMES + ("wrist.x",))
    add(_pose(rng).ravel()[:-3], HAND_POSE_NAMES[:-3])  # missing names
    add(_pose(rng).ravel()[order[:40]], np.array(HAND_POSE_NAMES)[order[:40]])
    add(_pose(rng).ravel().astype(np.float32))
    add(list(_pose(rng).ravel()))
    return out


def _bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("reading", ["abduction_first", "flexion_first"])
@pytest.mark.parametrize("name", list(SIM_RIGS))
def test_compiled_flags_and_values_agree_with_numpy(pipelines, current, name, reading, rng):
    if reading == "abduction_first":
        numpy_p, compiled_p = pipelines[name]
    else:
        numpy_p, compiled_p = FlexionFirstInNumpy(current[name]), current[name]
    gloves = _gloves(rng)
    flags = set()
    for batched in (False, True):
        if batched:
            old, new = numpy_p.prepare_hands(gloves), compiled_p.prepare_hands(gloves)
        else:
            old = [numpy_p.prepare_hands([g])[0] for g in gloves]
            new = [compiled_p.prepare_hands([g])[0] for g in gloves]
        for g, a, b in zip(gloves, old, new):
            assert a.flag == b.flag, (g.stamp_ns, a.flag, b.flag)
            flags.add(a.flag)
            if a.flag:
                assert b.flexion is None and b.effector is None
                continue
            np.testing.assert_allclose(b.flexion, a.flexion, rtol=0, atol=1e-12)
            np.testing.assert_allclose(b.abduction, a.abduction, rtol=0, atol=1e-12)
            if a.effector is not None:
                np.testing.assert_allclose(b.effector.q, a.effector.q, rtol=0, atol=1e-12)
                np.testing.assert_array_equal(b.effector.q0, b.effector.q)  # the kernel clipped it already
            else:
                assert b.effector is None
    assert flags == {"", "glove_invalid", "glove_out_of_range"}


@pytest.mark.parametrize("reading", ["abduction_first", "flexion_first"])
@pytest.mark.parametrize("name", list(SIM_RIGS))
def test_compiled_single_samples_equal_the_batch_bit_for_bit(pipelines, current, name, reading, rng):
    p = pipelines[name][1] if reading == "abduction_first" else current[name]
    gloves = _gloves(rng)
    batch = p.prepare_hands(gloves)
    for g, b in zip(gloves, batch):
        a = p.prepare_hands([g])[0]
        assert a.flag == b.flag
        if a.flag:
            continue
        assert _bits(a.flexion, b.flexion) and _bits(a.abduction, b.abduction)
        if a.effector is not None:
            assert _bits(a.effector.q, b.effector.q) and _bits(a.effector.q0, b.effector.q0)
            assert a.effector.report.pairs == b.effector.report.pairs
        # the effector's own preparation, from the angles alone, computes the same joints (LeapEffector.target)
        again = p.effector.prepare(a.flexion[None], a.abduction[None])[0]
        if a.effector is not None:
            assert _bits(again.q, a.effector.q)


def test_the_compiled_leap_retargeting_is_the_numpy_one(pipelines, rng):
    numpy_p, compiled_p = pipelines["leap_hand"]
    flexion, abduction = rng.uniform(-1.5, 3.0, (300, 15)), rng.uniform(-1.5, 1.5, (300, 15))  # clipping too
    old = numpy_p.effector.retarget.from_angles(flexion, abduction)
    new = np.array([p.q for p in compiled_p.effector.prepare(flexion, abduction)])
    np.testing.assert_array_equal(new, old)  # the same multiply, add and clip: no libm in between


def test_the_bounds_are_the_pipelines(pipelines):
    """Each bound sits where the kernel reads it (hand_kernels' index names), not only in the same order."""
    _, p = pipelines["leap_hand"]
    limits = p._glove.limits
    assert limits[hand_kernels.MAX_ROTATION_SQ] == MAX_JOINT_ROTATION**2
    assert limits[hand_kernels.MIN_FLEXION] == MIN_FLEXION and limits[hand_kernels.MAX_FLEXION] == MAX_FLEXION
    assert limits[hand_kernels.MAX_ABDUCTION] == MAX_ABDUCTION and limits[hand_kernels.TWIST_NOISE] == TWIST_NOISE


def test_hand_values_reads_names_in_any_order(rng):
    v = rng.normal(size=45)
    assert hand_values(HAND_POSE_NAMES, v) is v  # no look-up, no copy, in the expected order
    same = tuple(str(n) for n in np.array(HAND_POSE_NAMES))  # equal, not identical
    assert np.array_equal(hand_values(same, v), v)
    order = rng.permutation(45)
    assert np.array_equal(hand_values(tuple(np.array(HAND_POSE_NAMES)[order]), v[order]), v)
    assert np.array_equal(hand_values(np.array(HAND_POSE_NAMES)[order], v[order]), v)  # names in an array
    pose = hand_pose_from_values(HAND_POSE_NAMES, v)
    assert np.array_equal(pose.ravel(), v) and not np.shares_memory(pose, v)
    with pytest.raises(KeyError):
        hand_values(HAND_POSE_NAMES[1:], v[1:])
