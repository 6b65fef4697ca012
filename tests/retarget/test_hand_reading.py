"""The human hand pose is read as anatomy allows (issue 42, item 2): flexion first, abduction the bone's
angle out of its plane of curling, so a deep fist's sideways deviation stays small and a thumb turned
about its own bone reads the same at every turn; "out of range" is what no human hand does. Checked on
IWER's shipped hand poses and on sweeps of finger flexion and thumb twist, through both input paths."""

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.human import smplx
from teleprev.messages import JointSample
from teleprev.rig import load_rig
from teleprev_devices.webxr import hands
from tests.helpers import hand_poses
from tests.helpers.hand_poses import (
    IWER_POSE_NAMES,
    THUMB_TWIST_SWEEP_DEG,
    flexed_hand,
    iwer_pose,
    through_vmc,
    through_webxr,
    thumb_twist,
    with_thumb_twist,
)

THUMB = [smplx.JOINT_INDEX[j] for j in ("thumb1", "thumb2", "thumb3")]


@pytest.fixture(scope="module")
def pipelines():
    """(the current format's pipeline, format 4's), on the default rig (LEAP Hand)."""
    rig = load_rig()
    return build_pipeline(rig), build_pipeline(rig, session_format=4)


@pytest.fixture(scope="module")
def sweep():
    return hand_poses.sweep()


def _angles(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return smplx.angles_from_hand_pose(hands.hand_pose(joints).reshape(15, 3))


def test_iwers_shipped_poses_are_read_and_their_thumb_twists_are_what_a_hand_makes():
    twists = {n: np.degrees(thumb_twist(iwer_pose(n))) for n in IWER_POSE_NAMES}
    assert -90 < twists["relaxed"] < -70 and -80 < twists["point"] < -60 and -115 < twists["pinch"] < -95
    pinch_f, pinch_a = _angles(iwer_pose("pinch"))
    thumb1 = smplx.JOINT_INDEX["thumb1"]
    # the pinch's thumb crosses towards the index: flexed, and its metacarpal inside the human bounds
    assert 0.7 < pinch_f[thumb1] < 1.3 and abs(pinch_a[thumb1]) < 0.8
    point_f, point_a = _angles(iwer_pose("point"))
    curled = [smplx.JOINT_INDEX[f"{f}2"] for f in ("middle", "ring", "pinky")]
    # the curled fingers' middle joints (hinges) flex ~80 degrees and deviate only a few degrees
    assert (point_f[curled] > 1.2).all() and (np.abs(point_a[curled]) < 0.2).all()


@pytest.mark.parametrize("flexion_deg", [90.0, 100.0, 110.0])
def test_a_deep_fists_sideways_deviation_reads_as_what_it_is(flexion_deg):
    deviation = 5.0
    joints = flexed_hand(flexion_deg, deviation, 8.0)
    f, a = _angles(joints)
    for finger in ("ring", "pinky"):
        j = smplx.JOINT_INDEX[f"{finger}1"]
        assert np.degrees(f[j]) == pytest.approx(flexion_deg, abs=1e-6)
        assert np.degrees(a[j]) == pytest.approx(deviation, abs=1e-6)
        # the same from the joint positions alone: the proximal bone's angle out of its plane of curling
        base = joints[hands.JOINT_INDEX[f"{finger}-finger-phalanx-proximal"], :3]
        tip = joints[hands.JOINT_INDEX[f"{finger}-finger-phalanx-intermediate"], :3]
        bone = (tip - base) / np.linalg.norm(tip - base)
        parent = hands.bone_frames(joints)[hands.JOINT_INDEX[f"{finger}-finger-metacarpal"]]
        sideways = parent[:, 2] @ bone  # +z of the SMPL-X hand frame: towards the thumb
        assert np.degrees(np.arcsin(sideways)) == pytest.approx(deviation, abs=1e-6)
        # abduction first, the same few degrees read many times larger (at 90 degrees, as 90): what
        # flagged real clips
        _, old = smplx.angles_from_hand_pose_abduction_first(hands.hand_pose(joints).reshape(15, 3))
        assert abs(np.degrees(old[j]) - deviation) > 3 * deviation


@pytest.mark.parametrize("pose", IWER_POSE_NAMES)
def test_the_thumbs_reading_does_not_move_through_any_twist_of_its_metacarpal(pose):
    base = iwer_pose(pose)
    readings = np.array([np.concatenate(_angles(with_thumb_twist(base, np.radians(t)))) for t in THUMB_TWIST_SWEEP_DEG])
    assert [round(np.degrees(thumb_twist(with_thumb_twist(base, np.radians(t))))) for t in (-150, 60)] == [-150, 60]
    # the thumb's angles (flexion and abduction of its three joints) are the same at every twist
    thumb = readings[:, THUMB + [15 + j for j in THUMB]]
    assert np.ptp(thumb, axis=0).max() < 1e-9
    old = np.array([np.concatenate(smplx.angles_from_hand_pose_abduction_first(
        hands.hand_pose(with_thumb_twist(base, np.radians(t))).reshape(15, 3))) for t in THUMB_TWIST_SWEEP_DEG])
    assert np.ptp(old[:, THUMB[0]]) > 1.0  # abduction first, the thumb's reading flipped somewhere in the sweep


def _flags(pipeline, samples) -> list[str]:
    return [h.flag for h in pipeline.prepare_hands(samples)]


def test_no_realistic_pose_is_rejected_on_the_webxr_path(pipelines, sweep):
    current, format4 = pipelines
    for what, joints in sweep.items():
        samples = through_webxr(joints)
        assert _flags(current, samples).count("glove_out_of_range") == 0, what
    # abduction first (format 4) rejected IWER's pinch and part of each sweep
    assert _flags(format4, through_webxr([iwer_pose("pinch")])) == ["glove_out_of_range"]
    assert _flags(format4, through_webxr(sweep["flexion"])).count("glove_out_of_range") > 0


def test_no_realistic_pose_is_rejected_on_the_vmc_path_and_it_reads_as_webxr_does(pipelines, sweep):
    current, _ = pipelines
    joints = sweep["iwer"] + sweep["thumb_twist"][::3] + sweep["flexion"][::4]
    vmc, xr = through_vmc(joints), through_webxr(joints)
    got, want = current.prepare_hands(vmc), current.prepare_hands(xr)
    assert [h.flag for h in got] == [""] * len(joints)
    for a, b in zip(got, want):  # the two paths send float32: the same angles to within that
        np.testing.assert_allclose(a.flexion, b.flexion, atol=2e-4)
        np.testing.assert_allclose(a.abduction, b.abduction, atol=2e-4)


@pytest.mark.parametrize("what, flexion, abduction", [
    ("a knuckle bent back past what a finger bends", -1.4, 0.0),
    ("a finger curled past 160 degrees", 2.8, 0.0),
    ("a finger straight out sideways", 0.3, 1.4),
])
def test_what_no_hand_does_is_still_out_of_range(pipelines, what, flexion, abduction):
    current, _ = pipelines
    f, a = np.full(15, 0.2), np.zeros(15)
    f[smplx.JOINT_INDEX["middle1"]], a[smplx.JOINT_INDEX["middle1"]] = flexion, abduction
    samples = through_webxr([flexed_hand(0.0, 0.0, 0.0)])  # a plausible hand first
    assert _flags(current, samples) == [""]
    bad = JointSample(0, smplx.HAND_POSE_NAMES, smplx.hand_pose_from_angles(f, a).ravel())
    assert _flags(current, [bad]) == ["glove_out_of_range"], what
