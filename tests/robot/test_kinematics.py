"""Forward kinematics: the numpy fast path against pytorch-kinematics, and poses the reference implies."""

import math

import numpy as np
import pytest

from teleprev.robot.model import load_robot
from teleprev.transforms import make_transform, rpy_to_matrix


@pytest.mark.parametrize("name", ["leap_hand_right", "xarm6", "xarm7", "xarm6_leap_hand"])
def test_fast_path_matches_pytorch_kinematics(name, rng):
    from teleprev.robot.batched import BatchedKinematics

    model = load_robot(name)
    q = model.sample_uniform(1000, rng)
    ours = model.fk(q).world
    theirs = BatchedKinematics(model).fk(q).world
    assert np.abs(ours[..., :3, 3] - theirs[..., :3, 3]).max() < 1e-9
    assert np.abs(ours - theirs).max() < 1e-9
    # one configuration at a time gives the same as the batch
    for i in range(0, 1000, 97):
        assert np.abs(model.fk(q[i]).world - ours[i]).max() < 1e-12


def test_pytorch_kinematics_own_urdf_loader_agrees(hand, rng):
    """An independent parse of the same file (pytorch-kinematics' loader, float32 origins) agrees to 1e-6 m."""
    import pytorch_kinematics as pk
    import torch

    chain = pk.build_chain_from_urdf(hand.urdf_path.read_bytes()).to(dtype=torch.float64)
    q = hand.sample_uniform(200, rng)
    names = chain.get_joint_parameter_names()
    frames = chain.forward_kinematics(torch.as_tensor(q[:, hand.indices(names)]))
    for tip in ("index_tip_head", "middle_tip_head", "ring_tip_head", "thumb_tip_head"):
        assert np.abs(frames[tip].get_matrix().numpy()[:, :3, 3] - hand.fk(q).position(tip)).max() < 1e-6


def _t(xyz, rpy):
    return make_transform(rpy_to_matrix(*rpy), xyz)


def test_all_zero_leap_hand_tips_match_reference_table(hand):
    """Compose the reference table's rows by hand (robots.md) and compare with FK at q = 0."""
    h = 1.57079
    base = _t((0, 0.038, 0.098), (0, -h, 0))
    index = (
        base
        @ _t((-0.0070, 0.0230, -0.0187), (h, h, 0))
        @ _t((-0.0122, 0.0381, 0.0145), (-h, 0, h))
        @ _t((0.015, 0.0143, -0.013), (h, -h, 0))
        @ _t((0, -0.0361, 0.0002), (0, 0, 0))
        @ _t((0, -0.048, 0.015), (0, 0, 0))
    )
    thumb = (
        base
        @ _t((-0.0693, -0.0012, -0.0216), (0, h, 0))
        @ _t((0, 0.0143, -0.013), (h, -h, 0))
        @ _t((0, 0.0145, -0.017), (-h, 0, 0))
        @ _t((0, 0.0466, 0.0002), (0, 0, 3.14159))
        @ _t((0, -0.06, -0.015), (0, 0, 0))
    )
    poses = hand.fk(np.zeros(16))
    assert np.allclose(poses.position("index_tip_head"), index[:3, 3], atol=1e-12)
    assert np.allclose(poses.position("thumb_tip_head"), thumb[:3, 3], atol=1e-12)
    # fingers of the flat hand point the same way and sit side by side, 45 mm apart
    tips = [poses.position(f"{f}_tip_head") for f in ("index", "middle", "ring")]
    assert abs(np.linalg.norm(tips[0] - tips[1]) - 0.0454) < 1e-3
    assert abs(tips[0][2] - tips[2][2]) < 1e-3


def test_xarm6_home_pose(xarm6):
    """At zero the flange sits at (207, 0, 112) mm pointing straight down (UFactory's published home)."""
    t = xarm6.fk(np.zeros(6)).matrix("link_eef")
    assert np.allclose(t[:3, 3], [0.207, 0.0, 0.112], atol=1e-9)
    assert np.allclose(t[:3, :3], np.diag([1.0, -1.0, -1.0]), atol=1e-9)


def test_xarm6_matches_published_dh(xarm6, rng):
    """The URDF joint origins and UFactory's standard DH parameters describe the same arm."""
    d = [0.267, 0, 0, 0.3425, 0, 0.097]
    a = [0, 0.28948866, 0.0775, 0, 0.076, 0]
    alpha = [-math.pi / 2, 0, -math.pi / 2, math.pi / 2, -math.pi / 2, 0]
    offset = [0, -1.3849179, 1.3849179, 0, 0, 0]
    for q in xarm6.sample_uniform(50, rng):
        t = np.eye(4)
        for i in range(6):
            th = q[i] + offset[i]
            ct, st, ca, sa = math.cos(th), math.sin(th), math.cos(alpha[i]), math.sin(alpha[i])
            t = t @ np.array(
                [
                    [ct, -st * ca, st * sa, a[i] * ct],
                    [st, ct * ca, -ct * sa, a[i] * st],
                    [0, sa, ca, d[i]],
                    [0, 0, 0, 1],
                ]
            )
        # the published a2 (289.48866 mm) and the URDF's hypot(53.5, 284.5) = 289.48661 mm differ by 2 um
        assert np.allclose(xarm6.fk(q).position("link_eef"), t[:3, 3], atol=1e-5)


def test_limits_and_names_come_from_the_urdf(hand, xarm6):
    assert hand.joint_names == tuple(str(i) for i in range(16))
    i = hand.joint_index["12"]
    assert (hand.lower[i], hand.upper[i]) == (-0.349, 2.094)
    assert np.all(hand.velocity_limit == 8.48)
    assert xarm6.upper[2] == pytest.approx(0.19198)
    assert np.all(xarm6.velocity_limit == pytest.approx(3.14))


def test_mimic_joints_follow_their_driver():
    gripper = load_robot("xarm6_parallel_gripper")
    assert gripper.joint_names[-1] == "gripper"
    poses = gripper.fk(gripper.vector({"gripper": 0.08}))
    gap = np.linalg.norm(poses.position("jaw_left") - poses.position("jaw_right"))
    assert gap == pytest.approx(0.08, abs=1e-9)


def test_mounted_hand_follows_the_flange():
    mounted = load_robot("xarm6_leap_hand")
    hand = load_robot("leap_hand_right")
    q_arm = np.array([0.3, -0.2, -0.5, 0.1, 0.4, -0.3])
    q_hand = hand.sample_uniform(1, np.random.default_rng(1))[0]
    q = mounted.vector({**dict(zip([f"joint{i}" for i in range(1, 7)], q_arm)), **hand.as_dict(q_hand)})
    poses = mounted.fk(q)
    mount = mounted.parent_joint["base"].origin
    expected = poses.matrix("link_eef") @ mount @ hand.fk(q_hand).matrix("thumb_tip_head")
    assert np.allclose(poses.matrix("thumb_tip_head"), expected, atol=1e-12)
