"""sim.camera: a synthetic view of the scene with the robot in it, JPEG-encoded like a webcam's.

On a physics rig (DeviceContext.physics) it renders the physics world (MuJoCo, from a copy of the world
made in the camera's own thread, teleprev.world.host.WorldMirror) from the same viewpoints and field of
view; `depth = true` also renders each frame's depth image (metres, 0 where nothing is in range), kept as
`last_depth` and published beside the frame, with the same stamp, on /camera/<name>/depth (16-bit counts of
0.1 mm, as a D405's) with its intrinsics on /camera/<name>/calibration. The kinematic world has no depth."""

from __future__ import annotations

import math
from collections import deque
from typing import Literal

import cv2
import numpy as np

from teleprev.devices import CameraInfo, DepthSample, DeviceContext, DeviceError, ImageSample, Sample, StreamSpec
from teleprev_devices.sim.device import SimDevice, TimingSettings, timing
from teleprev_devices.sim.render import VIEWS, FrameFinish, SceneRenderer
from teleprev_devices.sim.world import shared_world


# latency: exposure read-out + USB, more than a frame's render time
@timing(rate_hz=30.0, latency_ms=20.0, jitter_ms=1.0, clock_offset_s=-42.0, clock_drift_ppm=-18.0)
class CameraSettings(TimingSettings):
    width: int = 640
    height: int = 480
    view: Literal["front", "side", "top"] = "front"
    fov_deg: float = 60.0  # horizontal field of view
    jpeg_quality: int = 85
    noise: float = 2.0  # pixel noise (standard deviation, 0..255 scale), so that frames differ
    label: bool = True  # print the device name and session time in a corner
    depth: bool = False  # physics rig: render and record each frame's depth image too

    def __post_init__(self):
        super().__post_init__()
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise ValueError(f"width and height must be 16..4096, got {self.width}x{self.height}")
        if not 10 <= self.fov_deg <= 150:
            raise ValueError(f"fov_deg must be 10..150, got {self.fov_deg}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 1..100, got {self.jpeg_quality}")
        if self.noise < 0:
            raise ValueError(f"noise must be >= 0, got {self.noise}")
        if self.view not in VIEWS:
            raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {self.view!r}")


class SimCamera(SimDevice[CameraSettings], kind="camera", stream="image", payload="image"):
    """ImageSample (JPEG) on /camera/<name>/image, frame_id = the device name."""

    acquire_on_time = True  # the picture shows the world at the moment of exposure

    def __init__(self, name: str, settings: CameraSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.world = shared_world(context)
        self.physics = context.physics
        self.last_depth = None  # physics, depth = true: the latest frame's depth image (metres)
        self._depths: deque = deque()  # depth counts of the frames acquired and not yet delivered, in order
        if self.physics is not None and settings.fov_deg != 60.0:
            raise self.bad_setting("fov_deg", "the physics world's cameras have a 60 degree field of view; "
                                              f"got {settings.fov_deg:g}")
        if settings.depth and self.physics is None:
            raise self.bad_setting("depth", "only a physics rig's camera renders depth ([sim] world = \"physics\")")

    def streams(self) -> list[StreamSpec]:
        streams = super().streams()
        if self.settings.depth:
            streams += [StreamSpec(self.topic("depth"), "depth", self.settings.rate_hz),
                        StreamSpec(self.topic("calibration"), "calibration", self.settings.rate_hz)]
        return streams

    def _open(self) -> None:
        s = self.settings
        self._depths.clear()
        if self.physics is not None:
            self.mirror = self.physics.mirror()  # made and used on this device's reader thread (its GL context)
            self.finish = FrameFinish(s.width, s.height, s.noise, s.seed)
            return
        self.renderer = SceneRenderer(self.world.model, s.width, s.height, s.view, s.fov_deg, s.noise, s.seed)

    def disconnect(self) -> None:
        super().disconnect()
        mirror = getattr(self, "mirror", None)
        if mirror is not None:  # its GL contexts are this thread's (the runner disconnects on the reading thread)
            mirror.close_renderers()

    def _render(self, true_ns: int):
        if self.physics is not None:
            s = self.settings
            frame = self.mirror.render(s.view, s.width, s.height, s.depth)
            self.last_depth = frame.depth
            if s.depth:
                self._depths.append(_counts(frame.depth))
            return self.finish(cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR), self._label(true_ns))
        q = self.world.joints()
        return self.renderer.render(q, self.world.scene(true_ns, q), self._label(true_ns))

    def _acquire(self, true_ns: int) -> ImageSample:
        img = self._render(true_ns)
        ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, self.settings.jpeg_quality])
        if not ok:
            raise DeviceError("JPEG encoding failed", f"device {self.name!r}")
        return ImageSample(0, self.name, buf.tobytes(), "jpeg")

    def read(self, timeout_s: float) -> list[Sample]:
        """The frames, and with depth = true each one's depth and calibration, stamped alike (frames are
        delivered in the order they were acquired)."""
        out = super().read(timeout_s)
        if not self.settings.depth:
            return out
        s = self.settings
        fx = s.width / 2 / math.tan(math.radians(s.fov_deg) / 2)
        for frame in list(out):
            stamp = frame.payload.stamp_ns
            out.append(Sample(self.topic("depth"), DepthSample(stamp, self.name, self._depths.popleft(), _DEPTH_UNIT)))
            out.append(Sample(self.topic("calibration"), CameraInfo(
                stamp, self.name, s.width, s.height, (fx, 0.0, (s.width - 1) / 2, 0.0, fx, (s.height - 1) / 2,
                                                      0.0, 0.0, 1.0), (0.0,) * 5)))
        return out

    def _label(self, true_ns: int) -> str:
        if not self.settings.label:
            return ""
        seconds = (true_ns - self.context.clock.start_ns) / 1e9
        return f"{self.name}  t={seconds:7.2f}s"


_DEPTH_UNIT = 0.0001  # metres per count: 0.1 mm, a D405's


def _counts(metres: np.ndarray) -> np.ndarray:
    """Depth in metres as 16-bit counts of _DEPTH_UNIT; beyond 6.55 m, as nothing in range, 0."""
    counts = np.rint(metres / _DEPTH_UNIT)
    counts[counts > 65535] = 0
    return counts.astype(np.uint16)
