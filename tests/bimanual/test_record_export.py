"""A bimanual session recorded unattended with `teleprev record rigs/sim_bimanual.toml`, exported with
LeRobot's bimanual naming, loaded back with LeRobotDataset exactly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from teleprev.assembly import motion_limits
from teleprev.rig import load_rig, side_rig
from teleprev.session.reader import SessionReader
from tests.helpers.bimanual_export import within
from tests.helpers.cli import teleprev

ROOT = Path(__file__).resolve().parents[2]
RIG = ROOT / "rigs" / "sim_bimanual.toml"


def expected_names() -> list[str]:
    arm = [f"joint{i}" for i in range(1, 7)]
    hand = [str(i) for i in range(16)]
    return [f"{side}_{role}.{j}" for side in ("left", "right") for role, joints in (("arm", arm), ("hand", hand))
            for j in joints]


def test_session_records_both_sides(session):
    rig = load_rig(RIG)
    with SessionReader(session) as r:
        sides = {side: json.loads(text) for side, text in r.metadata["sides"].items()}
        assert sides["left"]["arm"] == "arm_left" and sides["left"]["robot"] == "xarm6_leap_hand_left"
        for side in ("left", "right"):
            limits = motion_limits(side_rig(rig, side))
            for kind in ("arm", "hand"):
                msgs = [m.payload for m in r.messages([f"/command/{side}/{kind}"])]
                assert len(msgs) > 100, f"{side} {kind}: {len(msgs)} commands"
                assert msgs[0].names == tuple(limits[kind]["names"])
            assert sum(1 for _ in r.messages([f"/pipeline/{side}/corrected"])) > 100
        assert "/command/arm" not in r.topics  # no single-arm stream in a bimanual session
        # both robots in one /tf tree: each side's links under "world" at its mount
        frames = {}
        for m in r.messages(["/tf"]):
            for t in m.payload.transforms:
                frames[(t.parent, t.child)] = t
        for side in ("left", "right"):
            root = frames[("world", f"{side}/link_base")]
            np.testing.assert_allclose(root.translation, rig.sides[side].section.mount_xyz)
            assert (f"{side}/link_eef", f"{side}/base") in frames and (f"{side}/base", f"{side}/palm_lower") in frames
        assert {p.split("/")[0] for p, _ in frames} == {"world", "left", "right"}
    info = teleprev("info", session)
    assert info.returncode == 0 and "never engaged" not in info.stdout


def test_audit_checks_each_side_against_its_own_limits(session):
    from teleprev.evaluation.audit import audit_session

    report = audit_session(session)
    assert [s.topic for s in report.streams] == ["/command/left/arm", "/command/left/hand", "/command/right/arm",
                                                 "/command/right/hand"]
    assert all(s.commands > 100 for s in report.streams)
    assert report.ok, report.as_dict()
    assert report.hand_state_samples > 200 and report.hand_state_colliding == 0


def test_export_uses_lerobot_bimanual_names_and_loads_back_exactly(session, dataset, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    ds = LeRobotDataset("lab/bimanual", root=dataset, video_backend="pyav")
    for feature in ("action", "observation.state"):
        assert ds.meta.features[feature]["names"] == expected_names()
        assert tuple(ds.meta.features[feature]["shape"]) == (44,)
    assert tuple(ds.meta.features["observation.images.cam_right"]["shape"]) == (120, 160, 3)
    assert tuple(ds[len(ds) - 1]["observation.images.cam_right"].shape) == (3, 120, 160)
    # The left half is what the left side's command streams give on their own (a single-arm export of them):
    # sides are concatenated, not altered.
    # (no split at a gap in either export: one side's streams may pause where the other's do not)
    left = _export(session, tmp_path / "left", ["/arm/arm_left/state", "/hand/hand_left/state"],
                   ["/command/left/arm", "/command/left/hand"])
    ds = _export(session, tmp_path / "whole", ["arm_state", "effector_state"], ["arm_command", "effector_command"])
    assert ds.meta.features["action"]["names"] == expected_names()
    assert len(ds) > 30
    for feature in ("action", "observation.state"):
        both = np.stack([ds[i][feature].numpy() for i in range(len(ds))])
        alone = np.stack([left[i][feature].numpy() for i in range(len(left))])
        assert within(both[:, :22], alone), (feature, len(both), len(alone))


def _export(session, root: Path, state: list[str], action: list[str]):
    """`teleprev export` of the session with a recipe of these state and action streams, loaded back."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    recipe = root.with_suffix(".toml")
    recipe.write_text("[export]\nmax_gap_ms = 60000.0\n" + "".join(
        f'\n[[feature]]\nname = "{name}"\nstreams = {json.dumps(streams)}\n'
        for name, streams in (("observation.state", state), ("action", action))))
    ran = teleprev("export", session, "--repo-id", f"lab/{root.name}", "--root", root, "--recipe", recipe)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    return LeRobotDataset(f"lab/{root.name}", root=root, video_backend="pyav")


def test_the_dataset_audit_measures_each_side_as_lerobot_loads_it(dataset):
    """`teleprev audit DATASET --config sim_bimanual.toml`: each side's columns (by name) against its own limits,
    the figures those of the actions lerobot loads (at the frames' timestamps)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.evaluation.audit import audit_path

    report = audit_path(dataset, RIG)
    ds = LeRobotDataset("lab/bimanual", root=dataset, video_backend="pyav")
    rows = [ds.hf_dataset[i] for i in range(len(ds.hf_dataset))]
    t = np.array([float(r["timestamp"]) for r in rows])
    episode = np.array([int(r["episode_index"]) for r in rows])
    action = np.array([np.asarray(r["action"], dtype=float) for r in rows])
    within_episode = episode[1:] == episode[:-1]  # (a gap may split the session: each episode on its own)
    rig = load_rig(RIG)
    assert report.note == "" and len(report.streams) == 4
    for k, (side, kind) in enumerate((s, k) for s in ("left", "right") for k in ("arm", "hand")):
        stream = report.streams[k]
        limits = motion_limits(side_rig(rig, side))[kind]
        assert stream.topic == f"action[{side} {'arm' if kind == 'arm' else 'end effector'}]"
        assert stream.commands == len(ds) and stream.position_outside == 0
        assert stream.speed_limit == float(limits["velocity"].min())
        cols = [expected_names().index(f"{side}_{kind}.{j}") for j in limits["names"]]
        v = (np.diff(action[:, cols], axis=0) / np.diff(t)[:, None])[within_episode]
        assert np.isclose(stream.speed_max, np.abs(v).max(), rtol=1e-4)
        # (an action is a command stamped with its frame's time: no bound on the ratio, as single-arm)


def test_an_act_trains_on_the_bimanual_export(policy):
    """lerobot-train (a tiny ACT, two steps on CPU) takes the export as it is: both sides' vectors and the camera
    (the policy test_rollout.py rolls out)."""
    config = json.loads((policy / "config.json").read_text())
    assert config["input_features"]["observation.state"]["shape"] == [44]
    assert config["input_features"]["observation.images.cam_right"]["shape"] == [3, 120, 160]
    assert config["output_features"]["action"]["shape"] == [44]
