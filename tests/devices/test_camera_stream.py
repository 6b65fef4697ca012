"""opencv.camera reading a network stream from a real HTTP MJPEG server (teleprev/emulators/mjpeg_stream.py):
frames on the session clock, and a stream that stalls, ends, or whose server restarts, coming back."""

from __future__ import annotations

import time

import cv2
import numpy as np

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext, DeviceRunner
from teleprev.emulators.mjpeg_stream import MjpegServer
from teleprev_devices.opencv_camera import OpenCVCamera, OpenCVSettings
from tests.helpers.hardware import EventLog


class Frames(EventLog):
    def __init__(self):
        super().__init__()
        self.images = []

    def sink(self, sample, receive_ns):
        super().sink(sample, receive_ns)
        if sample.topic == "/camera/cam/image":
            self.images.append((receive_ns, sample.payload))


def test_a_stream_on_the_session_clock_that_stalls_ends_and_comes_back():
    server = MjpegServer(fps=30.0).start()
    clock = SessionClock()
    cam = OpenCVCamera("cam", OpenCVSettings(source=server.url, stall_timeout_s=0.5), DeviceContext(clock))
    log = Frames()
    runner = DeviceRunner(cam, log.sink, clock, reconnect_s=0.2).start()
    try:
        assert log.wait(lambda: len(log.images) >= 5), log.events
        time.sleep(1.0)
        stamps = np.array([p.stamp_ns for _, p in log.images])
        received = np.array([r for r, _ in log.images])
        assert len(stamps) >= 25  # about 30 fps
        assert np.all(np.diff(stamps) > 0) and np.all(stamps <= received) and np.all(received - stamps < 50e6)
        img = cv2.imdecode(np.frombuffer(log.images[-1][1].data, np.uint8), cv2.IMREAD_COLOR)
        assert img.shape == (120, 160, 3) and log.images[-1][1].format == "jpeg"

        for fault, said in (("stall", "the stream stalled: no frame for"), ("end", "the stream ended")):
            errors, frames = log.count("error"), len(log.images)
            server.inject(fault, seconds=1.5)
            assert log.wait(lambda: log.count("error") > errors, timeout_s=3.0), log.events
            assert said in log.of("error")[-1]["message"]
            assert log.wait(lambda: len(log.images) > frames + 10, timeout_s=5.0), log.events  # it came back

        port = int(server.url.rsplit(":", 1)[1].split("/")[0])
        server.stop()  # the camera restarts: down for a moment, then back on the same address
        errors = log.count("error")
        assert log.wait(lambda: log.count("error") > errors, timeout_s=3.0)
        server = MjpegServer(fps=30.0, port=port).start()
        frames = len(log.images)
        assert log.wait(lambda: len(log.images) > frames + 10, timeout_s=5.0), log.events
        assert runner.stats().connects >= 4
    finally:
        runner.stop()
        server.stop()
