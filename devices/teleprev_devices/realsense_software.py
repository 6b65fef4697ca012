"""A RealSense camera made of librealsense's own software_device, for running realsense.camera without one.

The SDK builds the device, its sensors, stream profiles, intrinsics, extrinsics and depth unit from what is
declared here, and the frames fed in go through its sensors, frame callbacks and align exactly as a USB camera's do; the
plugin finds it through `realsense.add_software_device` and cannot tell the difference. Faults are what a
camera does: its frames stop (`pause`), its hardware clock jumps (`jump_clock_ms`), it is unplugged
(`unplug`: gone from the device list and silent) and plugged back in (`replug`).

    camera = SoftwareRealSense(serial="000000000405", model="D405").start()
    ...  # a rig with [devices.wrist] plugin = "realsense.camera", serial = "000000000405"
    camera.stop()

The scene is a tilted table at 0.3..0.9 m with a box sliding across it, 2 % holes (depth 0) and 0.5 mm of
sensor noise, colour a gradient; `depth_for(frame_number)` gives back the exact counts a frame was fed with, and `fed`
the hardware
time of each.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from teleprev_devices.realsense import add_software_device, remove_software_device

# What the two common models declare (librealsense's D400 documentation): a D405's depth unit is 0.1 mm and
# its colour comes from the depth module; a D435 counts millimetres and has a separate RGB camera 15 mm over.
MODELS = {
    "D405": {"scale": 0.0001, "sensors": ("Stereo Module",), "colour_offset_m": 0.0},
    "D435": {"scale": 0.001, "sensors": ("Stereo Module", "RGB Camera"), "colour_offset_m": 0.015},
}
_SCENE_FRAMES = 30  # distinct depth frames, cycled (a frame's counts are a function of its number)
_NOISE_FIELDS = 31  # sensor noise added to them, cycled at another period so that no two frames repeat


@dataclass
class FedFrame:
    number: int
    hardware_ms: float  # the timestamp the frame was fed with, on the camera's clock


class SoftwareRealSense:
    def __init__(self, serial: str = "000000000405", model: str = "D405", width: int = 640, height: int = 480,
                 fps: int = 30, clock_origin_ms: float = 12_345.0, keep_fed: int = 100_000):
        if model not in MODELS:
            raise ValueError(f"model must be one of {', '.join(MODELS)}, got {model!r}")
        import pyrealsense2 as rs

        self.rs, self.serial, self.model = rs, serial, model
        self.width, self.height, self.fps = width, height, fps
        spec = MODELS[model]
        self.depth_scale = spec["scale"]
        self.device = rs.software_device()
        self.device.register_info(rs.camera_info.name, f"Intel RealSense {model} (software_device)")
        self.device.register_info(rs.camera_info.serial_number, serial)
        sensors = [self.device.add_sensor(name) for name in spec["sensors"]]
        self._depth_sensor, self._colour_sensor = sensors[0], sensors[-1]
        self.intrinsics = self._intrinsics(rs)
        self._depth_profile = self._depth_sensor.add_video_stream(
            self._video_stream(rs, rs.stream.depth, 0, 2, rs.format.z16)).as_video_stream_profile()
        self._colour_profile = self._colour_sensor.add_video_stream(
            self._video_stream(rs, rs.stream.color, 1, 3, rs.format.bgr8)).as_video_stream_profile()
        self._depth_sensor.add_read_only_option(rs.option.depth_units, self.depth_scale)
        extrinsics = rs.extrinsics()
        extrinsics.rotation = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        extrinsics.translation = [spec["colour_offset_m"], 0.0, 0.0]
        self._depth_profile.register_extrinsics_to(self._colour_profile, extrinsics)
        self._scene = _scene(width, height, self.depth_scale)
        rng = np.random.default_rng(435)  # a D405's noise near 0.5 m is about 0.5 mm RMS
        sigma = 0.0005 / self.depth_scale
        self._noise = [np.rint(rng.normal(0, sigma, (height, width))).astype(np.int32) for _ in range(_NOISE_FIELDS)]
        self._colour = _colour(width, height)
        self._clock_origin_ms = clock_origin_ms
        self._mono0 = time.monotonic()
        self._jump_ms = 0.0
        self._paused = threading.Event()
        self._stopping = threading.Event()
        self._thread: threading.Thread | None = None
        self.fed: list[FedFrame] = []
        self._keep_fed = keep_fed
        self.number = 0

    def _intrinsics(self, rs):
        intr = rs.intrinsics()
        intr.width, intr.height = self.width, self.height
        intr.fx = intr.fy = 0.6 * self.width  # about a D405's 87 degrees across
        intr.ppx, intr.ppy = self.width / 2 - 0.5, self.height / 2 - 0.5
        intr.model, intr.coeffs = rs.distortion.brown_conrady, [0.0] * 5
        return intr

    def _video_stream(self, rs, kind, uid: int, bpp: int, fmt):
        vs = rs.video_stream()
        vs.type, vs.index, vs.uid = kind, 0, uid
        vs.width, vs.height, vs.fps, vs.bpp, vs.fmt = self.width, self.height, self.fps, bpp, fmt
        vs.intrinsics = self.intrinsics
        return vs

    # --- the camera's clock and frames ---

    def hardware_ms(self) -> float:
        return self._clock_origin_ms + (time.monotonic() - self._mono0) * 1000.0 + self._jump_ms

    def depth_for(self, number: int) -> np.ndarray:
        """The counts frame `number` was fed with (H, W) uint16: the scene, and the number itself in the first
        two pixels of the top row (low, high 16 bits) so that a frame read back names itself."""
        scene = self._scene[number % _SCENE_FRAMES]
        noise = self._noise[(number + number // _SCENE_FRAMES) % _NOISE_FIELDS]  # repeats after 930 frames
        depth = np.where(scene > 0, scene.astype(np.int32) + noise, 0).astype(np.uint16)
        depth[0, 0], depth[0, 1] = number & 0xFFFF, number >> 16
        return depth

    @staticmethod
    def number_of(depth: np.ndarray) -> int:
        """The frame number depth_for wrote into an unaligned depth image."""
        return int(depth[0, 0]) | int(depth[0, 1]) << 16

    def feed_one(self) -> FedFrame:
        """Feed the next depth and colour frame, with one hardware timestamp, now."""
        rs = self.rs
        self.number += 1
        stamp = self.hardware_ms()
        for sensor, profile, pixels, bpp in ((self._depth_sensor, self._depth_profile, self.depth_for(self.number), 2),
                                             (self._colour_sensor, self._colour_profile, self._colour, 3)):
            frame = rs.software_video_frame()
            frame.pixels, frame.bpp, frame.stride = pixels, bpp, bpp * self.width
            frame.timestamp, frame.domain = stamp, rs.timestamp_domain.hardware_clock
            frame.frame_number, frame.profile = self.number, profile
            if bpp == 2:
                frame.depth_units = self.depth_scale
            try:
                sensor.on_video_frame(frame)
            except RuntimeError:  # not streaming (not opened yet, or closed): its frames go nowhere then
                pass
        fed = FedFrame(self.number, stamp)
        if len(self.fed) < self._keep_fed:
            self.fed.append(fed)
        return fed

    def _run(self) -> None:
        period = 1.0 / self.fps
        due = time.monotonic()
        while not self._stopping.is_set():
            due += period
            if not self._paused.is_set():
                self.feed_one()
            delay = due - time.monotonic()
            if delay > 0:
                self._stopping.wait(delay)
            elif delay < -5 * period:
                due = time.monotonic()  # fell behind (a loaded machine): a camera drops frames, it does not burst

    # --- life cycle and faults ---

    def start(self) -> SoftwareRealSense:
        add_software_device(self.serial, self.device)
        self._thread = threading.Thread(target=self._run, name=f"realsense-{self.serial}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stopping.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        remove_software_device(self.serial)

    def pause(self) -> None:
        """The frames stop (a stalled USB link); the camera stays listed."""
        self._paused.set()

    def resume(self) -> None:
        self._paused.clear()

    def jump_clock_ms(self, ms: float) -> None:
        """The hardware clock jumps by `ms` (a firmware reset; negative: it goes back)."""
        self._jump_ms += ms

    def unplug(self) -> None:
        self.pause()
        remove_software_device(self.serial)

    def replug(self) -> None:
        add_software_device(self.serial, self.device)
        self.resume()

    def __enter__(self) -> SoftwareRealSense:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def _scene(width: int, height: int, scale_m: float) -> list[np.ndarray]:
    rng = np.random.default_rng(405)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    table = 0.3 + 0.6 * yy / height + 0.05 * xx / width  # metres
    frames = []
    for i in range(_SCENE_FRAMES):
        cx = width * (0.2 + 0.6 * i / _SCENE_FRAMES)
        box = (np.abs(xx - cx) < width / 8) & (np.abs(yy - height / 2) < height / 6)
        metres = np.where(box, table - 0.12, table)
        counts = np.round(metres / scale_m).astype(np.uint16)
        counts[rng.random(counts.shape) < 0.02] = 0  # holes: no depth
        frames.append(counts)
    return frames


def _colour(width: int, height: int) -> np.ndarray:
    yy, xx = np.mgrid[0:height, 0:width]
    return np.stack([(xx * 255 // width), (yy * 255 // height), np.full_like(xx, 128)], axis=-1).astype(np.uint8)
