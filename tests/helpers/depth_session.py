"""A session recorded live from a depth camera: realsense.camera on a software_device RealSense, run by the
session's DeviceRunner into the session Recorder (the writer thread, chunked zstd MCAP), beside an arm stream
and one episode, as `teleprev record` would record them. For the depth tests and bench/depth.py."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev import topics as T
from teleprev.devices import DeviceContext, DeviceRunner, Event, JointSample, Logged, Sample, SessionClock
from teleprev.session.recorder import LAG_BUDGET_S, Recorder, RecordingSummary
from teleprev_devices.realsense import RealSenseCamera, RealSenseSettings
from teleprev_devices.realsense_software import SoftwareRealSense
from tests.helpers.wait import wait_until

ARM = tuple(f"joint{i}" for i in range(1, 7))


@dataclass
class DepthRecording:
    path: Path
    summary: RecordingSummary
    camera_stats: object  # the runner's RunnerStats at the end
    counters: dict[str, int]  # the plugin's
    seconds: float


def record_depth_session(path: Path, camera: SoftwareRealSense, seconds: float, name: str = "wrist",
                         **settings) -> DepthRecording:
    """Record `seconds` of `camera` (started here) through realsense.camera into `path`: one episode
    around all of it, the arm's joints at 100 Hz."""
    clock = SessionClock()
    recorder = Recorder(path, {"rig": {"robot": "xarm6_leap_hand", "end_effector": "leap_hand"}},
                        lag_budget_s=LAG_BUDGET_S).start()  # a live session's: frames shed when the writer lags

    def sink(sample: Sample, receive_ns: int) -> None:
        recorder.log(Logged(sample.topic, receive_ns, sample.payload))

    def episode(event: str) -> None:
        now = clock.now_ns()
        data = {"event": event, "episode": 0, "task": "pick"}
        sink(Sample(T.EPISODE, Event(now, "teleprev.EpisodeEvent", data)), now)

    device = RealSenseCamera(name, RealSenseSettings(serial=camera.serial, width=camera.width, height=camera.height,
                                                     fps=camera.fps, **settings), DeviceContext(clock))
    stop = threading.Event()

    def arm() -> None:
        while not stop.wait(0.01):
            now = clock.now_ns()
            q = np.sin(np.arange(6) + now / 1e9)
            sink(Sample("/arm/arm/state", JointSample(now, ARM, q)), now)

    camera.start()
    runner = DeviceRunner(device, sink, clock).start()
    arm_thread = threading.Thread(target=arm, daemon=True)
    arm_thread.start()
    try:
        wait_until(lambda: runner.stats().topics.get(device.depth_topic, 0) > 0, 10.0,
                   what="the depth camera's first frames")
        episode("start")
        time.sleep(seconds)
        episode("stop")
        time.sleep(0.2)  # frames of the last instant: exported frames need their neighbours
    finally:
        stats = runner.stats()
        counters = device.counters()
        stop.set()
        arm_thread.join()
        runner.stop()
        camera.stop()
    return DepthRecording(path, recorder.close(), stats, counters, seconds)



def depth_physics_rig(folder: Path, width: int = 160, height: int = 120) -> Path:
    """The physics rig (rigs/sim_physics.toml) with its camera at width x height rendering depth too."""
    import os
    import re

    from teleprev.rig import default_rig_path

    os.environ.setdefault("MUJOCO_GL", "egl")  # headless rendering, decided before the world imports mujoco
    text = (default_rig_path().parent / "sim_physics.toml").read_text()
    text = re.sub(r"(\[devices\.cam_front\][^\[]*?)width = 640\nheight = 480\n",
                  rf"\1width = {width}\nheight = {height}\ndepth = true\n", text, flags=re.S)
    if "depth = true" not in text:
        raise AssertionError("rigs/sim_physics.toml's camera no longer reads as this helper expects")
    path = folder / "sim_physics_depth.toml"
    path.write_text(text)
    return path
