"""A depth camera recorded live (realsense.camera -> DeviceRunner -> Recorder) reads back from the MCAP as
Foxglove shows it: depth as RawImage 16UC1 (or a 16-bit PNG) with its unit, the calibration on the depth's
frame, and the camera's frame on /tf."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.messages import CameraInfo, DepthSample, TransformsSample
from teleprev.session.reader import SessionReader
from teleprev_devices.realsense_software import SoftwareRealSense
from tests.helpers.depth_session import record_depth_session


@pytest.mark.parametrize("form, schema", [("raw", "foxglove.RawImage"), ("png", "foxglove.CompressedImage")])
def test_a_recorded_depth_camera_reads_back_exact_with_unit_calibration_and_tf(tmp_path, form, schema):
    camera = SoftwareRealSense(serial="000000000405", model="D405", width=160, height=120)
    rec = record_depth_session(tmp_path / "s.mcap", camera, 0.5, align_depth=False, depth_format=form,
                               parent_frame="link_base", mount_xyz=(0.05, 0.0, 0.1))
    assert rec.summary.errors == [] and rec.summary.streams["/camera/wrist/depth"].dropped == 0
    with SessionReader(rec.path) as r:
        schemas = r.schemas
        depth = [m.payload for m in r.messages(["/camera/wrist/depth"])]
        (info, *_) = [m.payload for m in r.messages(["/camera/wrist/calibration"])]
        tf = [m.payload for m in r.messages(["/tf"])]
    assert (schemas["/camera/wrist/depth"], schemas["/camera/wrist/calibration"], schemas["/tf"]) == (
        schema, "foxglove.CameraCalibration", "foxglove.FrameTransforms")
    assert len(depth) >= 10 and all(isinstance(d, DepthSample) and d.format == form for d in depth)
    assert depth[0].scale_m == pytest.approx(0.0001)
    assert all(np.array_equal(d.depth, camera.depth_for(SoftwareRealSense.number_of(d.depth))) for d in depth)
    assert isinstance(info, CameraInfo) and (info.frame_id, info.width, info.height) == ("wrist_depth", 160, 120)
    assert isinstance(tf[0], TransformsSample)
    chain = {(t.parent, t.child): t for t in tf[0].transforms}
    assert chain[("link_base", "wrist")].translation.tolist() == [0.05, 0.0, 0.1]
    assert ("wrist", "wrist_depth") in chain  # depth's own frame, for the point cloud
