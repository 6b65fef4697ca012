"""The pipeline's end effector is built from its row of the table, and only a Corrector brings model hashes."""

import dataclasses
import hashlib
from pathlib import Path

import pytest

from teleprev.assembly import build_pipeline
from teleprev.errors import UrdfError
from teleprev.evaluation.reproduce import rerun_session
from teleprev.paths import data_dir
from teleprev.pipeline.effectors import Effector, LeapEffector
from teleprev.rig import load_rig
from teleprev.robot.effectors import EFFECTORS
from teleprev.session.reader import SessionReader
from tests.helpers.sessions import RIGS, record_sim

SIM_RIGS = {"leap_hand": "sim.toml", "parallel_gripper": "sim_gripper.toml", "vacuum": "sim_vacuum.toml"}


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def pipelines():
    return {name: build_pipeline(load_rig(RIGS / rig)) for name, rig in SIM_RIGS.items()}


def test_every_row_of_the_table_has_a_sim_rig():
    assert set(SIM_RIGS) == set(EFFECTORS)
    assert {name: load_rig(RIGS / rig).effector for name, rig in SIM_RIGS.items()} == EFFECTORS


@pytest.mark.parametrize("name", list(EFFECTORS))
def test_the_pipeline_drives_the_rows_joints_from_the_rows_tcp(pipelines, name):
    row, p = EFFECTORS[name], pipelines[name]
    assert isinstance(p.effector, Effector)
    assert p.effector.spec is row
    assert p.effector.names == p.effector_names == row.joints
    assert p.arm.ik.tip == row.tcp_link
    # a hand that can collide with itself is corrected, and its commands checked exactly; nothing else is
    assert (p.effector.corrector is not None) == row.self_colliding
    assert (p.effector.guard.checker is not None) == row.self_colliding
    if row.self_colliding:
        assert p.effector.corrector.model.name == row.hand_urdf


def test_a_hand_whose_urdf_disagrees_with_its_row_is_refused(pipelines):
    leap = pipelines["leap_hand"].effector
    row = dataclasses.replace(leap.spec, joints=leap.spec.joints[::-1])
    cfg = pipelines["leap_hand"].cfg
    with pytest.raises(UrdfError, match="end-effector table"):
        LeapEffector(row, leap.model, leap.corrector, cfg, 0.05)


def test_only_the_leap_pipeline_has_model_hashes_and_they_are_the_shipped_files(pipelines):
    models = data_dir("models")
    assert pipelines["leap_hand"].model_hashes() == {
        "cpn": _sha256(models / "cpn_leap_hand.safetensors"), "ccn": _sha256(models / "ccn_leap_hand.safetensors"),
    }
    assert pipelines["parallel_gripper"].model_hashes() is None
    assert pipelines["vacuum"].model_hashes() is None


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    folder = tmp_path_factory.mktemp("effectors")
    for name in ("leap_hand", "parallel_gripper"):
        record_sim(folder / f"{name}.mcap", SIM_RIGS[name], seconds=1.5, engage_after=0.5)
    return folder


def test_a_session_records_model_hashes_for_the_leap_rig_only(sessions, pipelines):
    assert SessionReader(sessions / "leap_hand.mcap").metadata["models"] == pipelines["leap_hand"].model_hashes()
    assert "models" not in SessionReader(sessions / "parallel_gripper.mcap").metadata


def test_a_rerun_names_its_effector_and_compares_the_models(sessions):
    leap = rerun_session(sessions / "leap_hand.mcap")
    assert leap.effector is EFFECTORS["leap_hand"] and leap.models_match is True
    gripper = rerun_session(sessions / "parallel_gripper.mcap")
    assert gripper.effector is EFFECTORS["parallel_gripper"] and gripper.models_match is True  # no models to differ


def test_a_rerun_with_other_models_says_they_differ(sessions, tmp_path):
    from safetensors import safe_open
    from safetensors.numpy import save_file

    shipped = data_dir("models")
    (tmp_path / "cpn_leap_hand.safetensors").write_bytes((shipped / "cpn_leap_hand.safetensors").read_bytes())
    with safe_open(str(shipped / "ccn_leap_hand.safetensors"), framework="numpy") as f:
        meta, tensors = f.metadata(), {k: f.get_tensor(k) for k in f.keys()}
    tensors["layers.0.bias"] = tensors["layers.0.bias"] + 1e-6  # as if retrained: same CPN, another CCN
    save_file(tensors, str(tmp_path / "ccn_leap_hand.safetensors"), metadata=meta)
    assert rerun_session(sessions / "leap_hand.mcap", models=tmp_path).models_match is False
