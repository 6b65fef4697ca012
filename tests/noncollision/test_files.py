"""Model files: a corrupted, mismatched or wrong-shaped CPN/CCN file is refused with a message saying which and why."""

import json
import shutil

import numpy as np
import pytest
from safetensors import safe_open
from safetensors.numpy import save_file

from teleprev.errors import ModelError
from teleprev.noncollision.corrector import Corrector
from teleprev.noncollision.mlp import load_model
from teleprev.paths import data_dir

MODELS = data_dir("models")
CPN_FILE = MODELS / "cpn_leap_hand.safetensors"
CCN_FILE = MODELS / "ccn_leap_hand.safetensors"


def _read(path):
    with safe_open(str(path), framework="numpy") as f:
        return dict(f.metadata()), {k: f.get_tensor(k) for k in f.keys()}


@pytest.fixture
def models(tmp_path):
    out = tmp_path / "models"
    out.mkdir()
    for f in (CPN_FILE, CCN_FILE):
        shutil.copy(f, out / f.name)
    return out


def test_shipped_copies_load(models, hand, hand_checker):
    corrector = Corrector.load(models, hand, hand_checker)
    assert corrector.cpn.link_names == hand_checker.link_names


@pytest.mark.parametrize("keep", [0, 7, 100, -64])
def test_truncated_file_refused(models, hand, hand_checker, keep):
    path = models / CPN_FILE.name
    data = path.read_bytes()
    path.write_bytes(data[:keep] if keep >= 0 else data[:keep])
    with pytest.raises(ModelError, match="truncated or corrupted") as err:
        Corrector.load(models, hand, hand_checker)
    assert str(path) in str(err.value)


def test_garbled_header_refused(models, hand):
    path = models / CCN_FILE.name
    data = bytearray(path.read_bytes())
    data[8:40] = b"x" * 32
    path.write_bytes(bytes(data))
    with pytest.raises(ModelError, match="truncated or corrupted"):
        load_model(path, "ccn", hand)


def test_other_urdf_refused(models, hand, hand_checker):
    meta, tensors = _read(models / CCN_FILE.name)
    meta["urdf_sha256"] = "ab" * 32
    save_file(tensors, str(models / CCN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="different URDF .*retrain") as err:
        Corrector.load(models, hand, hand_checker)
    assert CCN_FILE.name in str(err.value)


def test_wrong_shapes_refused(models, hand, hand_checker):
    meta, tensors = _read(models / CPN_FILE.name)
    tensors["layers.1.weight"] = np.zeros(tensors["layers.1.weight"].shape[:-1] + (7,), dtype=np.float32)
    save_file(tensors, str(models / CPN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match=r"tensor layers.1.weight has shape .* needs"):
        Corrector.load(models, hand, hand_checker)


def test_architecture_metadata_disagreeing_with_tensors_refused(models, hand):
    meta, tensors = _read(models / CCN_FILE.name)
    meta["hidden"] = json.dumps(json.loads(meta["hidden"])[:-1])  # one layer fewer than stored
    save_file(tensors, str(models / CCN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="do not match the architecture"):
        load_model(models / CCN_FILE.name, "ccn", hand)


def test_missing_tensor_and_nan_refused(models, hand, hand_checker):
    meta, tensors = _read(models / CPN_FILE.name)
    bad = dict(tensors)
    bad["layers.0.bias"] = np.full_like(bad["layers.0.bias"], np.nan)
    save_file(bad, str(models / CPN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="non-finite"):
        load_model(models / CPN_FILE.name, "cpn", hand, hand_checker.link_names)
    del tensors["layers.0.bias"]
    save_file(tensors, str(models / CPN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="missing: layers.0.bias"):
        load_model(models / CPN_FILE.name, "cpn", hand, hand_checker.link_names)


def test_kind_and_names_checked(models, hand, hand_checker):
    with pytest.raises(ModelError, match="this is a CPN file, a CCN was expected"):
        load_model(models / CPN_FILE.name, "ccn", hand)
    meta, tensors = _read(models / CPN_FILE.name)
    meta["link_names"] = json.dumps(list(reversed(hand_checker.link_names)))
    save_file(tensors, str(models / CPN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="differ from the checker's"):
        load_model(models / CPN_FILE.name, "cpn", hand, hand_checker.link_names)


def test_not_a_teleprev_file_refused(models, hand):
    save_file({"w": np.zeros(3, dtype=np.float32)}, str(models / CCN_FILE.name))
    with pytest.raises(ModelError, match="not a teleprev CPN/CCN file"):
        load_model(models / CCN_FILE.name, "ccn", hand)


def test_ccn_trained_against_another_cpn_refused(models, hand, hand_checker):
    meta, tensors = _read(models / CPN_FILE.name)
    tensors["layers.0.bias"] = tensors["layers.0.bias"] + np.float32(1e-3)  # a different (retrained) CPN
    save_file(tensors, str(models / CPN_FILE.name), metadata=meta)
    with pytest.raises(ModelError, match="trained against another CPN"):
        Corrector.load(models, hand, hand_checker)


def test_missing_models_explained(tmp_path, models, hand, hand_checker):
    with pytest.raises(ModelError, match="no such models folder"):
        Corrector.load(tmp_path / "absent", hand, hand_checker)
    (models / CCN_FILE.name).unlink()
    with pytest.raises(ModelError, match="no CCN for robot 'leap_hand_right'.*train-ccn"):
        Corrector.load(models, hand, hand_checker)
