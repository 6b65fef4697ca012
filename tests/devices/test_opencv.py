"""opencv.camera reading a real video file written here with cv2.VideoWriter."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.errors import ConfigError, DeviceError
from teleprev_devices.opencv_camera import OpenCVCamera, OpenCVSettings

FRAMES, FPS, W, H = 12, 40.0, 160, 120


def square_x(i: int) -> int:
    return 10 + 10 * i


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """A white square moving 10 px right per frame on black."""
    path = tmp_path_factory.mktemp("video") / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), FPS, (W, H))
    assert writer.isOpened()
    for i in range(FRAMES):
        frame = np.zeros((H, W, 3), np.uint8)
        frame[40:80, square_x(i):square_x(i) + 20] = 255
        writer.write(frame)
    writer.release()
    return path


def read_all(cam, seconds, until=None):
    """What the camera gives in `seconds`, or (`until`: a count) as soon as it has that many: a fixed
    window would count the host's stalls, not the camera's frames."""
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end and (until is None or len(out) < until):
        out.extend(cam.read(0.05))
    return out


def decoded(sample):
    img = cv2.imdecode(np.frombuffer(sample.payload.data, np.uint8), cv2.IMREAD_GRAYSCALE)
    assert img is not None
    return img


def centre_x(img) -> float:
    cols = np.nonzero(img.max(axis=0) > 128)[0]
    return (cols.min() + cols.max() + 1) / 2


def test_plays_a_video_file_at_its_own_rate_then_goes_quiet(video):
    ctx = DeviceContext(SessionClock(), rig_dir=video.parent)
    cam = OpenCVCamera("cam", OpenCVSettings(source=video.name, jpeg_quality=90), ctx)
    assert cam.streams()[0].rate_hz == pytest.approx(FPS)
    cam.connect()
    try:
        t0 = time.monotonic()
        samples = read_all(cam, FRAMES / FPS + 0.3)
        assert len(samples) == FRAMES
        assert {s.topic for s in samples} == {"/camera/cam/image"}
        assert all(s.payload.format == "jpeg" and s.payload.frame_id == "cam" for s in samples)
        for i, s in enumerate(samples):
            img = decoded(s)
            assert img.shape == (H, W)
            assert abs(centre_x(img) - (square_x(i) + 10)) <= 1  # frame i, in order
        stamps = np.array([s.payload.stamp_ns for s in samples])
        assert np.allclose(np.diff(stamps), 1e9 / FPS, atol=1e3)  # paced at the file's 40 fps
        assert time.monotonic() - t0 >= (FRAMES - 1) / FPS
        assert cam.read(0.05) == []  # the end of a file is silence, not an error
    finally:
        cam.disconnect()


def test_loop_and_resize(video):
    ctx = DeviceContext(SessionClock())
    cam = OpenCVCamera("cam", OpenCVSettings(source=str(video), width=80, height=60, fps=200.0, loop=True), ctx)
    cam.connect()
    try:
        samples = read_all(cam, 10.0, until=FRAMES + 3)
        assert len(samples) > FRAMES + 2  # went round
        img = decoded(samples[FRAMES])
        assert img.shape == (60, 80)
        assert abs(centre_x(img) - (square_x(0) + 10) / 2) <= 1  # frame 0 again, half size
    finally:
        cam.disconnect()


def test_sources_that_cannot_be_opened_name_themselves(tmp_path):
    ctx = DeviceContext(SessionClock(), rig_dir=tmp_path)
    with pytest.raises(DeviceError, match="no such video file.*missing.mp4"):
        OpenCVCamera("cam", OpenCVSettings(source="missing.mp4"), ctx).connect()
    (tmp_path / "notes.txt").write_text("not a video")
    with pytest.raises(DeviceError, match=r"cannot open video file .*notes.txt"):
        OpenCVCamera("cam", OpenCVSettings(source="notes.txt"), ctx).connect()
    with pytest.raises(DeviceError, match=r"'cam' \(camera 97\).*cannot open camera index 97"):
        OpenCVCamera("cam", OpenCVSettings(source=97), ctx).connect()


def test_settings_from_a_rig(tmp_path):
    from teleprev.rig import load_rig

    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.cam]\nplugin = "opencv.camera"\nsource = 2\nwidth = 640\nheight = 480\n')
    s = load_rig(rig).devices["cam"].settings
    assert (s.source, s.width, s.height) == (2, 640, 480)
    rig.write_text('[devices.cam]\nplugin = "opencv.camera"\nsource = "rtsp://127.0.0.1/x"\nwidth = 640\n')
    with pytest.raises(ConfigError, match=r"\[devices.cam\].*width and height must both be"):
        load_rig(rig)
    rig.write_text('[devices.cam]\nplugin = "opencv.camera"\njpeg_quality = 0\n')
    with pytest.raises(ConfigError, match="jpeg_quality must be 1..100"):
        load_rig(rig)
