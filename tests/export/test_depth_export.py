"""Depth from a live-recorded session into a LeRobot dataset and back through LeRobotDataset: the feature
LeRobot 0.6 names <cam>_depth, flagged is_depth_map, quantised and encoded by lerobot's depth encoder, read
back in metres within the quantisation step of the depth it was recorded with."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from teleprev.errors import SessionError
from teleprev.export.recipe import load_recipe, recipe_from_table
from teleprev.export.run import ExportOptions, export
from teleprev.messages import DepthSample
from teleprev.session.reader import SessionReader
from teleprev_devices.realsense_software import SoftwareRealSense
from tests.helpers.depth_session import record_depth_session

W, H = 160, 120
DEPTH_MIN = 0.01  # lerobot.configs.video.DEFAULT_DEPTH_MIN (not imported here: lerobot loads in ~15 s)


def quant_step_m(depth_m):
    """LeRobot's log quantisation step at depth_m (lerobot.configs.video defaults: 0.01..10 m, shift 3.5 m,
    12 bits)."""
    from lerobot.configs.video import DEFAULT_DEPTH_MAX, DEFAULT_DEPTH_MIN, DEFAULT_DEPTH_SHIFT, DEPTH_QMAX

    span = math.log(DEFAULT_DEPTH_MAX + DEFAULT_DEPTH_SHIFT) - math.log(DEFAULT_DEPTH_MIN + DEFAULT_DEPTH_SHIFT)
    return (depth_m + DEFAULT_DEPTH_SHIFT) * span / DEPTH_QMAX


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp("depth") / "session.mcap"
    camera = SoftwareRealSense(serial="000000000405", model="D405", width=W, height=H)
    return record_depth_session(path, camera, 2.0, align_depth=False)


def recipe(*videos: dict, name: str = "depth.toml"):
    """State and action from the arm (the session has no hand), and these video features."""
    return recipe_from_table({"feature": [{"name": "observation.state", "streams": ["arm_state"]},
                                          {"name": "action", "streams": ["arm_state"], "timing": "next"}, *videos]},
                             name)


CAMERAS = {"name": "observation.images.{camera}", "streams": ["camera:*"]}


def recorded_depth(path) -> list[DepthSample]:
    with SessionReader(path) as r:
        return [m.payload for m in r.messages(["/camera/wrist/depth"])]


def test_the_default_recipe_takes_every_cameras_depth():
    (depth,) = [f for f in load_recipe("default").feature if f.name.endswith("_depth")]
    assert (depth.name, depth.streams) == ("observation.images.{camera}_depth", ("depth:*",))


def test_depth_exported_reads_back_through_lerobot_in_metres_within_the_quantisation(session, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    (depth,) = [f for f in load_recipe("default").feature if f.name.endswith("_depth")]
    root = tmp_path / "ds"
    export(ExportOptions([session.path], "lab/depth", root,
                         recipe(CAMERAS, {"name": depth.name, "streams": list(depth.streams)})))
    info = json.loads((root / "meta" / "info.json").read_text())
    feature = info["features"]["observation.images.wrist_depth"]
    assert feature["shape"] == [H, W, 1] and feature["info"]["is_depth_map"] is True
    assert feature["info"]["depth_unit"] == "m" and feature["info"]["video.codec"] == "hevc"
    assert feature["info"]["video.pix_fmt"] == "gray12le"
    assert info["features"]["observation.images.wrist"]["shape"] == [H, W, 3]

    ds = LeRobotDataset("lab/depth", root=root, video_backend="pyav", depth_output_unit="m")
    recorded = [s.metres() for s in recorded_depth(session.path)]
    assert len(ds) >= 15  # of about 60: a loaded machine may split the episode at a silent stream
    last = 0
    for k in range(0, len(ds), 7):
        got = ds[k]["observation.images.wrist_depth"].numpy().reshape(H, W)
        # the recorded frame it came from: the best match from the last one matched to 25 on (the scene
        # repeats every 30 frames)
        errors = [np.abs(got - r)[r >= DEPTH_MIN].max() for r in recorded[last:last + 26]]
        match = last + int(np.argmin(errors))
        last = match
        want = recorded[match]
        # in range: within half a quantisation step; holes (0: no depth) and anything nearer than lerobot's
        # depth_min (the frame number in the corner) come back as depth_min
        seen = want >= DEPTH_MIN
        assert np.all(np.abs(got - want)[seen] <= quant_step_m(want[seen]) / 2 + 1e-6)
        assert np.allclose(got[~seen], DEPTH_MIN, atol=1e-4)


def test_a_recipe_chooses_which_cameras_export_depth(session, tmp_path):
    root = tmp_path / "colour_only"
    export(ExportOptions([session.path], "lab/colour", root, recipe(CAMERAS)))
    features = json.loads((root / "meta" / "info.json").read_text())["features"]
    assert "observation.images.wrist" in features and "observation.images.wrist_depth" not in features

    root = tmp_path / "depth_only"
    export(ExportOptions([session.path], "lab/depth_only", root,
                         recipe({"name": "observation.images.{camera}_depth", "streams": ["depth:wrist"]})))
    features = json.loads((root / "meta" / "info.json").read_text())["features"]
    assert "observation.images.wrist_depth" in features and "observation.images.wrist" not in features

    with pytest.raises(SessionError, match="no camera device 'front' with a depth stream .*found: wrist"):
        export(ExportOptions([session.path], "lab/x", tmp_path / "x",
                             recipe({"name": "observation.images.{camera}_depth", "streams": ["depth:front"]})))
