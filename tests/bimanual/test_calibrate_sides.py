"""`teleprev calibrate` on a bimanual rig: the simulated operator holds each pose with both hands, and each side
gets its own file, fitted from its own glove and suit. The left glove (the operator's left hand) is mirrored
into the right hand's terms first, as the pipeline reads it: the symmetric sim operator's two files then give
the same joint scales, and the rig takes them as each side's calibration."""

from __future__ import annotations

from pathlib import Path

import pytest

from teleprev.bimanual import side_calibration
from teleprev.retarget.calibration import load_calibration
from teleprev.rig import load_rig
from tests.helpers.cli import teleprev

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"
FLEXION = ("1", "2", "5", "6", "9", "10")


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory) -> tuple[Path, str]:
    out = tmp_path_factory.mktemp("cal") / "calib" / "ada.toml"
    run = teleprev("calibrate", RIG, "--out", out, "--hold", "0.6", "--seconds", "0.5", "--operator", "ada")
    assert run.returncode == 0, run.stdout + run.stderr
    return out, run.stdout


def test_each_side_gets_its_own_file_from_its_own_devices(calibrated):
    out, said = calibrated
    assert not out.exists()
    files = {side: out.with_name(f"ada_{side}.toml") for side in ("left", "right")}
    cals = {side: load_calibration(path) for side, path in files.items()}
    for side in ("left", "right"):
        assert f"[sides.{side}] calibration" in said and "on the left side" in said
        assert cals[side].calibration.operator == "ada"
        # the sim's fist closes well past its open hand: real scales, of the right sign on both hands
        assert all(0.5 < cals[side].joints[j].scale < 3.0 and cals[side].joints[j].scale != 1.0 for j in FLEXION)
        assert abs(cals[side].calibration.suit_yaw) < 0.2  # the sim operator faces the robots
    for j in FLEXION:  # one symmetric operator, two hands: the same fit (each side's own noise)
        assert cals["left"].joints[j].scale == pytest.approx(cals["right"].joints[j].scale, rel=0.15), j


def test_a_rig_referencing_the_files_calibrates_each_side_with_its_own(calibrated, tmp_path):
    out, _ = calibrated
    text = RIG.read_text()
    for side in ("left", "right"):
        path = out.with_name(f"ada_{side}.toml")
        text = text.replace(f"[sides.{side}]\n", f'[sides.{side}]\ncalibration = "{path}"\n')
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(text)
    rig = load_rig(rig_path)
    for side in ("left", "right"):
        written = load_calibration(out.with_name(f"ada_{side}.toml"))
        assert side_calibration(rig, side).joints == written.joints


def test_a_side_without_a_glove_is_named(tmp_path):
    text = RIG.read_text().replace('glove = "glove_left"\n', "")
    rig_path = tmp_path / "rig.toml"
    rig_path.write_text(text)
    run = teleprev("calibrate", rig_path, "--out", tmp_path / "c.toml", "--hold", "0", "--seconds", "0.1")
    assert run.returncode != 0
    assert "[sides.left]" in run.stderr and "glove" in run.stderr
