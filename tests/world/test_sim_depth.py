"""sim.camera on a physics rig with depth = true records depth: each frame's depth image (0.1 mm counts)
and calibration beside it with the same stamp; a kinematic rig's camera has none and says so."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.errors import ConfigError
from teleprev.messages import CameraInfo, DepthSample, ImageSample
from teleprev.rig import default_rig_path, load_rig
from tests.helpers.wait import wait_until

PHYSICS_RIG = default_rig_path().parent / "sim_physics.toml"


def _camera(rig_path, **settings):
    rig = load_rig(rig_path)
    spec = next(d for d in rig.devices.values() if d.kind == "camera")
    context = rig.device_context(SessionClock())
    return spec.cls(spec.name, replace(spec.settings, **settings), context), context


def test_a_physics_camera_records_depth_beside_each_frame():
    camera, context = _camera(PHYSICS_RIG, depth=True, width=320, height=240)
    assert [s.topic.rsplit("/", 1)[1] for s in camera.streams()] == ["image", "depth", "calibration"]
    camera.connect()
    try:
        got = []
        wait_until(lambda: got.extend(camera.read(0.2)) or len(got) >= 9, 20.0, what="three frames with depth")
    finally:
        camera.disconnect()
        context.physics.close()
    images = [s.payload for s in got if isinstance(s.payload, ImageSample)]
    depths = [s.payload for s in got if isinstance(s.payload, DepthSample)]
    infos = [s.payload for s in got if isinstance(s.payload, CameraInfo)]
    assert len(images) == len(depths) == len(infos) >= 3
    assert [d.stamp_ns for d in depths] == [i.stamp_ns for i in images]
    d = depths[-1]
    assert d.depth.shape == (240, 320) and d.scale_m == 0.0001
    seen = d.metres()[d.depth > 0]
    assert 0.5 < float(np.median(seen)) < 4.0
    assert infos[0].k[0] == pytest.approx(160 / math.tan(math.radians(30)))


def test_a_kinematic_camera_refuses_depth():
    with pytest.raises(ConfigError, match="only a physics rig's camera renders depth"):
        _camera(default_rig_path(), depth=True)
