"""A bimanual session recorded unattended on rigs/sim_bimanual.toml, its default export and a tiny ACT trained
on it, once for the tests of this folder that read them (record, export, audit, replay, training, rollout)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.helpers.cli import teleprev

RIG = Path(__file__).resolve().parents[2] / "rigs" / "sim_bimanual.toml"


@pytest.fixture(scope="session")
def session(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bimanual") / "s.mcap"
    ran = teleprev("record", RIG, "--duration", "6", "--engage-after", "1.5", "--no-preview", "--out", out)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    return out


@pytest.fixture(scope="session")
def dataset(session, tmp_path_factory) -> Path:
    """The session's default export (lab/bimanual): both sides' 44-vectors and the right side's camera."""
    root = tmp_path_factory.mktemp("bimanual_ds") / "ds"
    ran = teleprev("export", session, "--repo-id", "lab/bimanual", "--root", root)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    return root


@pytest.fixture(scope="session")
def policy(dataset, tmp_path_factory) -> Path:
    """A tiny ACT trained by lerobot-train on the export (tests.helpers.policies): its pretrained_model folder."""
    from tests.helpers.policies import train_tiny_act

    return train_tiny_act(dataset, "lab/bimanual", tmp_path_factory.mktemp("bimanual_act") / "train")
