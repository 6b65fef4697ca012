"""Arm inverse kinematics on the xArm6."""

import numpy as np

from teleprev.robot.ik import ArmIK
from teleprev.transforms import rotation_error


def test_reaches_random_reachable_targets_within_limits(xarm6, rng):
    ik = ArmIK(xarm6, "link_eef")
    for _ in range(1000):
        q_true = xarm6.sample_uniform(1, rng)[0]
        target = ik.pose(q_true)
        start = xarm6.clip(q_true + rng.uniform(-0.2, 0.2, 6))
        result = ik.solve(target, start)
        assert xarm6.within_limits(result.q)
        reached = ik.pose(result.q)
        assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-3
        assert np.linalg.norm(rotation_error(target[:3, :3], reached[:3, :3])) < 0.01
        assert result.converged


def test_unreachable_target_reports_no_convergence_and_stays_in_limits(xarm6):
    ik = ArmIK(xarm6, "link_eef")
    target = ik.pose(np.zeros(6))
    target[:3, 3] = [2.0, 0.0, 0.5]  # two metres away: out of reach
    result = ik.solve(target, np.zeros(6))
    assert not result.converged
    assert xarm6.within_limits(result.q)
    assert result.position_error > 0.5


def test_warm_start_tracks_a_smooth_trajectory_in_few_iterations(xarm6):
    ik = ArmIK(xarm6, "link_eef")
    q = np.array([0.0, -0.3, -0.6, 0.0, 0.9, 0.0])
    home = ik.pose(q)
    iterations = []
    for k in range(240):
        target = home.copy()
        target[:3, 3] += 0.05 * np.array([np.sin(k / 40), np.cos(k / 50) - 1, np.sin(k / 60)])
        result = ik.solve(target, q)
        assert result.converged
        q = result.q
        iterations.append(result.iterations)
    assert np.mean(iterations) < 4


def test_tcp_offset_is_applied(xarm6):
    tcp = np.eye(4)
    tcp[2, 3] = 0.1
    ik = ArmIK(xarm6, "link_eef", tcp=tcp)
    pose = ik.pose(np.zeros(6))
    assert np.allclose(pose[:3, 3], [0.207, 0.0, 0.012], atol=1e-9)  # flange points down: 100 mm lower
