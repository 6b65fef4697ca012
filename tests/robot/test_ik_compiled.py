"""The compiled arm IK (ArmIK, ik_kernels.ik_solve) against the numpy solver formats 1 and 2 ran (NumpyArmIK).

Same algorithm, so the same answers to rounding: the 6x6 system is solved by Cholesky instead of numpy's
LU, so the last bits differ, but convergence, iteration counts and joint values agree, every result is
within the limits, and the same inputs give the same bits every time (in this process and in another).
"""

import subprocess
import sys

import numpy as np
import pytest

from teleprev.pipeline.older_formats import NumpyArmIK, NumpyArmRetargeter
from teleprev.retarget.arm import ArmRetargeter
from teleprev.robot.ik import ArmIK
from teleprev.robot.model import load_robot
from teleprev.transforms import axis_angle_to_matrix, rotation_error


@pytest.fixture(scope="module")
def iks(xarm6):
    return NumpyArmIK(xarm6, "link_eef"), ArmIK(xarm6, "link_eef")


def _bits(result) -> tuple:
    return (result.q.tobytes(), result.converged, result.iterations, result.position_error, result.rotation_error)


def _agree(a, b, q_tol=1e-6) -> bool:
    return a.converged == b.converged and a.iterations == b.iterations and np.abs(a.q - b.q).max() < q_tol


def test_reachable_targets_from_near_warm_starts_match_numpy(xarm6, iks, rng):
    numpy_ik, compiled_ik = iks
    agree = converged = 0
    for _ in range(1000):
        q_true = xarm6.sample_uniform(1, rng)[0]
        target = numpy_ik.pose(q_true)
        start = xarm6.clip(q_true + rng.uniform(-0.2, 0.2, 6))
        expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
        assert xarm6.within_limits(result.q)
        agree += _agree(expected, result)
        if not result.converged:
            continue
        converged += 1
        reached = numpy_ik.pose(result.q)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) <= compiled_ik.position_tolerance * (1 + 1e-9)
        assert np.linalg.norm(rotation_error(target[:3, :3], reached[:3, :3])) <= compiled_ik.rotation_tolerance * (
            1 + 1e-9
        )
        assert result.position_error <= compiled_ik.position_tolerance
        assert result.rotation_error <= compiled_ik.rotation_tolerance
    assert converged >= 995
    assert agree >= 995  # rounding may tip a tolerance test by one iteration, very rarely


def test_random_warm_starts_anywhere_match_numpy(xarm6, iks, rng):
    """Far starts: long iterations, joints pinned at limits, stalls and the short-stepped retry."""
    numpy_ik, compiled_ik = iks
    agree = converged = numpy_converged = 0
    n = 400
    for _ in range(n):
        q_true, start = xarm6.sample_uniform(2, rng)
        target = numpy_ik.pose(q_true)
        expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
        assert xarm6.within_limits(result.q)
        assert result.converged == (result.position_error <= compiled_ik.position_tolerance
                                    and result.rotation_error <= compiled_ik.rotation_tolerance)
        agree += _agree(expected, result)
        converged += result.converged
        numpy_converged += expected.converged
    assert agree >= 0.97 * n  # far from the answer, rounding can send the two down different valleys
    assert abs(converged - numpy_converged) <= 0.02 * n
    assert 0.1 * n < converged < 0.9 * n  # both outcomes (and so the retry) are exercised


def test_pinned_joints_match_numpy(xarm6, iks, rng):
    """Targets whose answer has joints on their limits: the pinned-joint rule decides the steps."""
    numpy_ik, compiled_ik = iks
    agree = 0
    for _ in range(200):
        q_true = xarm6.sample_uniform(1, rng)[0]
        pinned = rng.random(6) < 0.5
        q_true[pinned] = np.where(rng.random(pinned.sum()) < 0.5, xarm6.lower[pinned], xarm6.upper[pinned])
        target = numpy_ik.pose(q_true)
        start = xarm6.clip(q_true + rng.uniform(-0.3, 0.3, 6))
        expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
        assert xarm6.within_limits(result.q)
        agree += _agree(expected, result)
    assert agree >= 195


def test_unreachable_target_gives_numpys_answer_within_limits(xarm6, iks, rng):
    numpy_ik, compiled_ik = iks
    target = numpy_ik.pose(np.zeros(6))
    target[:3, 3] = [2.0, 0.0, 0.5]  # two metres away: out of reach
    for start in [np.zeros(6), *xarm6.sample_uniform(20, rng)]:
        expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
        assert not result.converged and not expected.converged
        assert result.iterations == expected.iterations == compiled_ik.max_iterations
        assert xarm6.within_limits(result.q)
        assert result.position_error > 0.5
        assert result.position_error == pytest.approx(expected.position_error, rel=1e-6, abs=1e-9)
        assert np.abs(result.q - expected.q).max() < 1e-6


def test_start_outside_the_limits_is_clipped_first(xarm6, iks):
    numpy_ik, compiled_ik = iks
    start = xarm6.upper + 1.0
    target = numpy_ik.pose(xarm6.clip(start))
    expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
    assert result.converged and result.iterations == expected.iterations == 0
    assert np.array_equal(result.q, xarm6.clip(start))


def test_same_inputs_give_the_same_bits(xarm6, iks, rng):
    _, compiled_ik = iks
    cases = []
    for _ in range(50):
        q_true, start = xarm6.sample_uniform(2, rng)
        cases.append((compiled_ik.pose(q_true), start))
    first = [_bits(compiled_ik.solve(t, s)) for t, s in cases]
    again = [_bits(compiled_ik.solve(t, s)) for t, s in cases]
    other = ArmIK(xarm6, "link_eef")
    assert first == again == [_bits(other.solve(t, s)) for t, s in cases]


def test_same_bits_in_another_process(xarm6, iks):
    _, compiled_ik = iks
    code = (
        "import numpy as np\n"
        "from teleprev.robot.ik import ArmIK\n"
        "from teleprev.robot.model import load_robot\n"
        "arm = load_robot('xarm6')\n"
        "ik = ArmIK(arm, 'link_eef')\n"
        "qs = np.random.default_rng(7).uniform(arm.lower, arm.upper, (20, 2, 6))\n"
        "print(b''.join(ik.solve(ik.pose(a), b).q.tobytes() for a, b in qs).hex())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    qs = np.random.default_rng(7).uniform(xarm6.lower, xarm6.upper, (20, 2, 6))
    assert out == b"".join(compiled_ik.solve(compiled_ik.pose(a), b).q.tobytes() for a, b in qs).hex()


def test_tcp_offset_and_a_prismatic_joint_match_numpy(rng):
    """A chain ending in a prismatic joint (the parallel gripper's driver), with a tool offset."""
    robot = load_robot("xarm6_parallel_gripper")
    tcp = np.eye(4)
    tcp[:3, 3] = [0.01, -0.02, 0.1]
    numpy_ik = NumpyArmIK(robot, "gripper_driver", tcp=tcp)
    compiled_ik = ArmIK(robot, "gripper_driver", tcp=tcp)
    assert not numpy_ik._revolute.all()
    chain = numpy_ik.chain
    agree = 0
    for _ in range(200):
        q_true = chain.sample_uniform(1, rng)[0]
        target = numpy_ik.pose(q_true)
        start = chain.clip(q_true + rng.uniform(-0.2, 0.2, len(q_true)))
        expected, result = numpy_ik.solve(target, start), compiled_ik.solve(target, start)
        assert chain.within_limits(result.q)
        assert result.converged
        agree += _agree(expected, result)
    assert agree >= 195


def test_rotation_error_kernel_matches_numpy_near_zero_and_pi(rng):
    from teleprev.kernels import ik as ik_kernels
    out = np.empty(3)
    for angle in [0.0, 1e-9, 1e-7, 0.3, 2.0, np.pi - 2e-4, np.pi - 1e-5, np.pi]:
        for _ in range(20):
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            base = axis_angle_to_matrix(rng.normal(size=3))
            current = np.eye(4)
            current[:3, :3] = base
            target = np.eye(4)
            target[:3, :3] = axis_angle_to_matrix(angle * axis) @ base
            ik_kernels.rotation_error_into(target, current, out)
            assert np.abs(out - rotation_error(target[:3, :3], base)).max() < 1e-6


# ---- the wrist-to-arm retargeter on the compiled IK ------------------------------------------------
def _retargeters(xarm6, **kwargs):
    numpy_arm = NumpyArmRetargeter(NumpyArmIK(xarm6, "link_eef"), **kwargs)
    return numpy_arm, ArmRetargeter(ArmIK(xarm6, "link_eef"), **kwargs)


def _wrist(rng, spread):
    w = np.eye(4)
    w[:3, :3] = axis_angle_to_matrix(rng.normal(size=3))
    w[:3, 3] = rng.uniform(-spread, spread, 3)
    return w


def test_retarget_target_matches_numpy_with_frame_scale_and_box(xarm6, rng):
    frame = axis_angle_to_matrix(np.array([0.1, -0.2, 1.3]))
    numpy_arm, compiled_arm = _retargeters(xarm6, scale=1.3, workspace_min=(0.1, -0.3, 0.0),
                                           workspace_max=(0.5, 0.3, 0.6), suit_to_robot=frame)
    q = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    anchor = numpy_arm.anchor(_wrist(rng, 0.3), q)
    clipped_any = unclipped_any = False
    for _ in range(300):
        wrist = _wrist(rng, 0.6)
        (expected, e_clip), (t, clip) = numpy_arm.target(anchor, wrist), compiled_arm.target(anchor, wrist)
        assert clip == e_clip
        assert np.abs(t - expected).max() < 1e-12
        assert np.all(t[:3, 3] >= numpy_arm.lo) and np.all(t[:3, 3] <= numpy_arm.hi)
        assert np.array_equal(t[3], [0.0, 0.0, 0.0, 1.0])
        clipped_any |= clip
        unclipped_any |= not clip
    assert clipped_any and unclipped_any


def test_retarget_solve_is_target_then_ik_in_one_call(xarm6, rng):
    numpy_arm, compiled_arm = _retargeters(xarm6, workspace_min=(0.0, -0.4, 0.0), workspace_max=(0.6, 0.4, 0.7))
    q = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    anchor = compiled_arm.anchor(np.eye(4), q)
    for _ in range(100):
        wrist = _wrist(rng, 0.1)
        wrist[:3, :3] = axis_angle_to_matrix(rng.normal(scale=0.2, size=3))
        result, clipped = compiled_arm.solve(anchor, wrist, q)
        target, t_clipped = compiled_arm.target(anchor, wrist)
        assert clipped == t_clipped
        assert _bits(result) == _bits(compiled_arm.ik.solve(target, q))
        expected, e_clipped = numpy_arm.solve(anchor, wrist, q)
        assert e_clipped == clipped
        assert _agree(expected, result)
        assert xarm6.within_limits(result.q)


def test_read_only_inputs_are_accepted(xarm6, iks):
    """Decoded messages are read-only arrays; the wrappers copy, so no other signature is compiled."""
    from teleprev.kernels import ik as ik_kernels
    _, compiled_ik = iks
    q = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    target = compiled_ik.pose(q)
    q.flags.writeable = False
    target.flags.writeable = False
    assert compiled_ik.solve(target, q).converged
    arm = ArmRetargeter(compiled_ik)
    wrist = np.eye(4)
    wrist.flags.writeable = False
    arm.solve(arm.anchor(wrist, q), wrist, q)
    assert len(ik_kernels.ik_solve.signatures) == len(ik_kernels.arm_solve.signatures) == 1
