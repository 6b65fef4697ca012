"""Calibration from open hand, fist and neutral wrist; the file round trip; its effect on retargeting."""

import numpy as np
import pytest

from teleprev.errors import ConfigError
from teleprev.human.smplx import JOINT_INDEX, hand_pose_from_angles
from teleprev.retarget.calibration import load_calibration, write_calibration
from teleprev.retarget.calibration_fit import FIST_TARGET, calibrate
from teleprev.retarget.hand import LeapRetargeter
from teleprev.transforms import axis_angle_to_matrix


def _poses(rng, flexion, abduction, n=30, noise=0.01):
    return hand_pose_from_angles(flexion + rng.normal(0, noise, (n, 15)), abduction + rng.normal(0, noise, (n, 15)))


def test_open_hand_maps_to_zero_and_fist_to_the_targets(hand, rng, tmp_path):
    # an operator whose open hand is slightly bent and spread, and whose fist closes only to 1.1 rad
    open_f, open_a = np.full(15, 0.15), np.full(15, 0.08)
    fist_f = np.full(15, 1.1)
    heading = 0.4  # the operator faces 0.4 rad left of the suit's x axis
    wrist = axis_angle_to_matrix(np.array([0.0, 0.0, heading + np.pi]))[None].repeat(20, axis=0)
    cal = calibrate(_poses(rng, open_f, open_a), _poses(rng, fist_f, open_a), wrist, operator="ada")
    path = write_calibration(cal, tmp_path / "cal.toml")
    cal = load_calibration(path)
    assert cal.calibration.operator == "ada"
    assert cal.calibration.suit_yaw == pytest.approx(-heading, abs=1e-9)
    retarget = LeapRetargeter(hand, cal.leap_map())
    q_open = hand.as_dict(retarget(hand_pose_from_angles(open_f, open_a)))
    q_fist = hand.as_dict(retarget(hand_pose_from_angles(fist_f, open_a)))
    for joint in map(str, range(16)):
        assert q_open[joint] == pytest.approx(0.0, abs=0.02)
    for joint, target in FIST_TARGET.items():
        assert q_fist[joint] == pytest.approx(target, abs=0.03)
    # yaw turns the operator's forward into the robot's +x
    forward = wrist[0] @ np.array([-1.0, 0.0, 0.0])
    assert (cal.suit_to_robot() @ forward)[:2] == pytest.approx([1.0, 0.0], abs=1e-9)


def test_a_joint_the_operator_did_not_move_keeps_scale_one(rng):
    f = np.full(15, 1.0)
    f[JOINT_INDEX["thumb3"]] = 0.0  # thumb tip never bent
    cal = calibrate(_poses(rng, np.zeros(15), np.zeros(15)), _poses(rng, f, np.zeros(15)), np.eye(3)[None])
    assert cal.joints["15"].scale == 1.0


def test_bad_calibration_files_are_named(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[joints."16"]\nscale = 1.0\n')
    with pytest.raises(ConfigError, match="unknown LEAP joint '16'"):
        load_calibration(bad)
    bad.write_text('[joints."3"]\nscale = "big"\n')
    with pytest.raises(ConfigError, match=r"bad.toml.*joints.3.scale.*expected a number"):
        load_calibration(bad)


def test_calibrate_command_on_the_sim_rig_writes_a_usable_file(tmp_path):
    """The guided command, unattended: the simulated operator holds each pose when asked. docs/recording.md's
    `--out calib/ada.toml` names a folder that does not exist yet: it is made."""
    from tests.helpers.cli import teleprev

    out = tmp_path / "calib" / "ada.toml"
    run = teleprev("calibrate", "--out", out, "--hold", "0.6", "--seconds", "0.5", "--operator", 'Ada "A." L')
    assert run.returncode == 0, run.stderr
    assert "[rig] calibration" in run.stdout
    cal = load_calibration(out)
    assert cal.calibration.operator == 'Ada "A." L'
    # the sim's fist closes well past its open hand, so the flexion joints got real scales
    assert all(0.5 < cal.joints[j].scale < 3.0 and cal.joints[j].scale != 1.0 for j in ("1", "2", "5", "6", "9", "10"))
    assert abs(cal.calibration.suit_yaw) < 0.2  # the sim operator faces the robot
