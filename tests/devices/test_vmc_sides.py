"""One VMC sender, both sides: vmc.glove and vmc.suit with `side = "left"` read the Left* bones. A mirrored
skeleton sent as real OSC over UDP on loopback gives the left glove the mirror of the right glove's pose and
the left suit the mirror of the right wrist (teleprev/human/mirror.py), which is what a bimanual rig's left
side takes; a frame that moves only one side reaches only that side's devices."""

from __future__ import annotations

import numpy as np
import pytest
from pythonosc.udp_client import SimpleUDPClient

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.human.mirror import mirror_hand_pose, mirror_wrist
from teleprev.transforms import quat_to_matrix
from teleprev_devices.vmc import VmcGlove, VmcSuit
from teleprev_devices.vmc.plugins import VmcSettings, VmcSuitSettings
from tests.helpers.ports import free_port
from tests.helpers.vmc import FINGERS, bone, both_sides, bundle, unity_quat
from tests.helpers.wait import wait_until

ARM = [("Hips", (0, 0.9, 0), (0, 0, 0, 1)), ("Spine", (0, 0.1, 0), (0, 0, 0, 1)),
       ("Chest", (0, 0.15, 0), (0, 0, 0, 1)), ("RightShoulder", (0.02, 0.2, 0), (0, 0, 0, 1)),
       ("RightUpperArm", (0.1, 0, 0), tuple(unity_quat([0.2, 1, -0.3], -0.5))),
       ("RightLowerArm", (0.3, 0, 0), tuple(unity_quat([0, 1, 0], -1.2))),
       ("RightHand", (0.25, 0, 0), tuple(unity_quat([1, 0.4, 0.2], 0.7)))]
# every right finger bone curled and turned a little differently (abduction, twist), so a sign slip shows
FINGER_BONES = [(f"Right{f}{p}", (0.03, 0, 0), tuple(unity_quat([0.1 * k, -0.2 + 0.05 * j, 1], -0.3 - 0.1 * k)))
                for k, f in enumerate(FINGERS) for j, p in enumerate(("Proximal", "Intermediate", "Distal"))]
ROOT = bone("root", (0, 0, 0.4), tuple(unity_quat([1, 0, 0], 0.1)), address="/VMC/Ext/Root/Pos")  # symmetric


@pytest.fixture
def devices():
    context = DeviceContext(SessionClock())
    port = free_port()
    made = {f"{kind}_{side}": cls(f"{kind}_{side}", settings(port=port, side=side), context)
            for kind, cls, settings in (("glove", VmcGlove, VmcSettings), ("suit", VmcSuit, VmcSuitSettings))
            for side in ("left", "right")}
    for d in made.values():
        d.connect()
    try:
        yield SimpleUDPClient("127.0.0.1", port), made
    finally:
        for d in made.values():
            d.disconnect()


def latest(device, timeout=5.0):
    got = []
    wait_until(lambda: got.extend(device.read(0.05)) or got, timeout, what=f"a sample from {device.name}")
    return got[-1].payload


def test_a_mirrored_operator_gives_the_left_side_the_mirror_of_the_right(devices):
    client, d = devices
    client.send(bundle(ROOT, *both_sides(ARM), *both_sides(FINGER_BONES)))
    right_hand, left_hand = latest(d["glove_right"]), latest(d["glove_left"])
    assert np.abs(right_hand.positions).max() > 0.2
    np.testing.assert_allclose(left_hand.positions, mirror_hand_pose(right_hand.positions, right_hand.names),
                               atol=1e-6)
    right, left = latest(d["suit_right"]), latest(d["suit_left"])
    position, rotation = mirror_wrist(right.position, quat_to_matrix(right.orientation))
    np.testing.assert_allclose(left.position, position, atol=1e-6)
    np.testing.assert_allclose(quat_to_matrix(left.orientation), rotation, atol=1e-6)
    assert left.position[1] > 0.3 > -0.3 > right.position[1]  # the operator's left (suit y) and right


def test_the_left_wrist_in_t_pose_points_its_fingers_to_the_operators_left(devices):
    client, d = devices
    t_pose = [(n, p, (0, 0, 0, 1)) for n, p, _ in ARM]
    client.send(bundle(*both_sides(t_pose)))
    left = latest(d["suit_left"])
    np.testing.assert_allclose(left.position, [0.0, 0.67, 1.35], atol=1e-6)
    r = quat_to_matrix(left.orientation)
    # the mirrored right-hand frame: fingers still along its -x (now the operator's left), palm down, thumb forward
    np.testing.assert_allclose(r @ [-1.0, 0, 0], [0, 1, 0], atol=1e-9)
    np.testing.assert_allclose(r @ [0, 1.0, 0], [0, 0, -1], atol=1e-9)
    np.testing.assert_allclose(r @ [0, 0, 1.0], [1, 0, 0], atol=1e-9)
    assert np.linalg.det(r) == pytest.approx(1.0)


def test_a_frame_moving_one_side_reaches_only_that_sides_devices(devices):
    client, d = devices
    client.send(bundle(*[bone(*b) for b in FINGER_BONES]))  # the right fingers only
    assert latest(d["glove_right"]) is not None
    client.send(bundle(*both_sides([("RightIndexProximal", (0.03, 0, 0), tuple(unity_quat([0, 0, 1], -0.4)))])[1:]))
    pose = latest(d["glove_left"])  # the left index alone: its flexion, the rest at rest
    assert np.count_nonzero(np.abs(pose.positions) > 1e-9) == 1
    assert d["glove_right"].read(0.2) == []  # nothing new for the right hand


def test_side_must_be_left_or_right():
    with pytest.raises(ValueError, match="side must be 'left' or 'right', got 'both'"):
        VmcSettings(side="both")
