"""realsense.camera: an Intel RealSense depth camera (D405, D435, ...) through librealsense (pyrealsense2, the
`realsense` extra): colour as JPEG on /camera/<name>/image, depth on /camera/<name>/depth, the intrinsics of the
depth image on /camera/<name>/calibration and the camera's frame on /tf.

    [devices.cam_wrist]
    plugin = "realsense.camera"
    serial = "123622270101"    # "" when one camera is plugged in; otherwise the error names those found
    width = 640                # colour (and, aligned, depth) resolution; the camera must offer it at fps
    height = 480
    fps = 30
    depth_width = 0            # 0: as colour; set both for a depth mode of its own (then align_depth = false
    depth_height = 0           #    records the depth in its own frame, "<name>_depth")
    align_depth = true         # depth reprojected onto the colour image (rs.align), frame and intrinsics of colour
    depth_format = "raw"       # "raw": foxglove.RawImage 16UC1; "png": 16-bit PNG (bench/depth.py compares them)
    jpeg_quality = 85
    stall_timeout_s = 1.0      # no frame for this long: unplugged or stalled, a device error
    parent_frame = "world"     # where the camera is mounted, for /tf
    mount_xyz = [0.0, 0.0, 0.0]
    mount_quat = [0.0, 0.0, 0.0, 1.0]   # x y z w

Depth is recorded in the camera's own unit, `get_depth_scale()` metres per count, which the session keeps with
the depth channel: a D435 counts 1 mm, a D405 0.1 mm, so a reader that assumed millimetres would be 10x off.

Time: every frame carries the camera's hardware timestamp; it is mapped onto the session clock by ClockSync
from (hardware time, receive time) pairs, as the VMC sender's clock is, with one offset for a frameset so that
depth and colour keep the difference their hardware stamps have. A hardware clock that jumps (forward by more
than the host waited, or backwards) is counted ("timestamp_jumps", shown as skipped input) and the mapping
starts over; frames the camera numbered but never delivered are counted as "lost_dropped_frames".

Unplugging: the frames stop; after stall_timeout_s read() raises a DeviceError, the runner marks a gap and
opens the camera again every reconnect period; while it is missing connect() names the cameras it does find,
and once it is back it streams again under the same topics.

Cameras are found by librealsense's context; `add_software_device` adds one made of the SDK's software_device
(teleprev_devices.realsense_software: the tests and bench/depth.py), which the plugin then opens, streams and
loses exactly as it would a USB camera.
"""

from __future__ import annotations

import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from teleprev.devices import (
    CameraInfo,
    ClockSync,
    DepthSample,
    Device,
    DeviceContext,
    DeviceError,
    ImageSample,
    Sample,
    StreamSpec,
    Transform,
    TransformsSample,
    transforms,
)

_TF = "/tf"
_JUMP_NS = 100_000_000  # hardware time ahead of the host's by more than this between frames: the clock jumped
_INFO_PERIOD_NS = 1_000_000_000  # calibration and /tf again every second (Foxglove may open the file anywhere)
_QUEUE = 64  # frames waiting for read() (1 s of depth and colour at 30 fps)

_software_devices: dict[str, Any] = {}  # serial -> rs.device made of a software_device (add_software_device)
_software_lock = threading.Lock()


def add_software_device(serial: str, device: Any) -> None:
    """Make a software_device visible to the plugin as if it were plugged in."""
    with _software_lock:
        _software_devices[serial] = device


def remove_software_device(serial: str) -> None:
    """Unplug it: the plugin no longer finds it (its frames stop with whoever fed them)."""
    with _software_lock:
        _software_devices.pop(serial, None)


def connected_cameras(rs) -> dict[str, tuple[str, Any]]:
    """serial -> (camera name, rs.device) of every camera librealsense finds, software devices included."""
    found: dict[str, tuple[str, Any]] = {}
    for dev in rs.context().query_devices():
        found[dev.get_info(rs.camera_info.serial_number)] = (dev.get_info(rs.camera_info.name), dev)
    with _software_lock:
        for serial, dev in _software_devices.items():
            found[serial] = (dev.get_info(rs.camera_info.name), dev)
    return found


@dataclass
class RealSenseSettings:
    serial: str = ""
    width: int = 640
    height: int = 480
    fps: int = 30
    depth_width: int = 0
    depth_height: int = 0
    align_depth: bool = True
    depth_format: str = "raw"
    jpeg_quality: int = 85
    stall_timeout_s: float = 1.0
    parent_frame: str = "world"
    mount_xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mount_quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)

    def __post_init__(self):
        for key in ("width", "height"):
            if not 16 <= getattr(self, key) <= 8192:
                raise ValueError(f"{key} must be 16..8192, got {getattr(self, key)}")
        if (self.depth_width == 0) != (self.depth_height == 0) or not (
                self.depth_width == 0 or 16 <= self.depth_width <= 8192 and 16 <= self.depth_height <= 8192):
            raise ValueError(f"depth_width and depth_height must both be 0 (as colour) or 16..8192, got "
                             f"{self.depth_width}x{self.depth_height}")
        if not 1 <= self.fps <= 1000:
            raise ValueError(f"fps must be 1..1000, got {self.fps}")
        if self.depth_format not in ("raw", "png"):
            raise ValueError(f"depth_format must be \"raw\" or \"png\", got {self.depth_format!r}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 1..100, got {self.jpeg_quality}")
        if not 0.05 <= self.stall_timeout_s <= 60:
            raise ValueError(f"stall_timeout_s must be 0.05..60, got {self.stall_timeout_s}")
        if not self.parent_frame:
            raise ValueError("parent_frame must not be empty")
        norm = float(np.linalg.norm(self.mount_quat))
        if not abs(norm - 1.0) < 1e-3:
            raise ValueError(f"mount_quat must be a unit quaternion (x y z w), got {list(self.mount_quat)}")


@dataclass
class _Stream:
    """One opened stream: its profile and its intrinsics."""

    profile: Any
    intrinsics: Any


class RealSenseCamera(Device[RealSenseSettings], kind="camera", sdk_module="pyrealsense2", extra="realsense"):
    """Colour (JPEG), depth (16-bit, the camera's unit), calibration and /tf of one RealSense camera."""

    def __init__(self, name: str, settings: RealSenseSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.image_topic, self.depth_topic = self.topic("image"), self.topic("depth")
        self.calibration_topic = self.topic("calibration")
        self.where = f"device {name!r} (RealSense {settings.serial or 'any'})"
        self.depth_frame = name if settings.align_depth else f"{name}_depth"
        self.depth_scale: float | None = None  # of the first camera opened: another unit is another camera
        self._sensors: list[Any] = []
        self._frames: queue.Queue | None = None
        self._align = None
        self._counters = {"timestamp_jumps": 0, "lost_dropped_frames": 0, "unpaired_frames": 0}
        self._counter_lock = threading.Lock()

    def streams(self) -> list[StreamSpec]:
        fps = float(self.settings.fps)
        return [StreamSpec(self.image_topic, "image", fps), StreamSpec(self.depth_topic, "depth", fps),
                StreamSpec(self.calibration_topic, "calibration", 1e9 / _INFO_PERIOD_NS)]

    def endpoint(self) -> str:
        return f"RealSense {self.settings.serial}" if self.settings.serial else "RealSense (the only one connected)"

    def counters(self) -> dict[str, int]:
        with self._counter_lock:
            return dict(self._counters)

    def _count(self, key: str, n: int = 1) -> None:
        with self._counter_lock:
            self._counters[key] += n

    # --- opening ---

    def connect(self) -> None:
        rs = self.import_sdk()
        self._rs = rs
        s = self.settings
        try:
            found = connected_cameras(rs)
        except RuntimeError as exc:
            raise DeviceError(f"librealsense cannot list cameras: {exc}", self.where) from None
        listing = ", ".join(f"{serial} ({name})" for serial, (name, _) in sorted(found.items())) or "none"
        if s.serial:
            if s.serial not in found:
                raise DeviceError(f"no RealSense camera with serial {s.serial} is connected; found: {listing}",
                                  self.where)
            name, device = found[s.serial]
        elif len(found) == 1:
            ((serial, (name, device)),) = found.items()
        else:
            raise DeviceError("no RealSense camera is connected" if not found else
                              f"{len(found)} RealSense cameras are connected ({listing}): set serial", self.where)
        self.camera_name = name
        try:
            self._open(rs, device)
        except RuntimeError as exc:  # pyrealsense2's errors derive from RuntimeError
            self.disconnect()
            raise DeviceError(f"cannot open {name}: {exc}", self.where) from None
        self.sync = ClockSync()
        self._last_hw_ns = self._last_receive_ns = None
        self._last_number: dict[int, int] = {}
        self._last_frame_ns = self.context.clock.now_ns()
        self._info_due_ns = 0

    def _open(self, rs, device) -> None:
        s = self.settings
        depth_size = (s.depth_width or s.width, s.depth_height or s.height)
        wanted = {rs.stream.depth: ((rs.format.z16,), depth_size), rs.stream.color: ((rs.format.bgr8, rs.format.rgb8),
                                                                                    (s.width, s.height))}
        by_sensor: dict[int, list[Any]] = {}
        chosen: dict[Any, _Stream] = {}
        sensors = list(device.query_sensors())
        offered: dict[Any, set[str]] = {kind: set() for kind in wanted}
        for i, sensor in enumerate(sensors):
            for profile in sensor.get_stream_profiles():
                kind = profile.stream_type()
                if kind not in wanted or kind in chosen or not profile.is_video_stream_profile():
                    continue
                video = profile.as_video_stream_profile()
                formats, size = wanted[kind]
                offered[kind].add(f"{video.width()}x{video.height()}@{profile.fps()}")
                if profile.format() in formats and (video.width(), video.height()) == size and profile.fps() == s.fps:
                    chosen[kind] = _Stream(profile, video.get_intrinsics())
                    by_sensor.setdefault(i, []).append(profile)
        for kind, what in ((rs.stream.depth, "depth"), (rs.stream.color, "colour")):
            if kind not in chosen:
                formats, (w, h) = wanted[kind]
                raise DeviceError(f"the camera offers no {what} stream of {w}x{h} at {s.fps} fps; it offers "
                                  f"{', '.join(sorted(offered[kind])) or 'none'}", self.where)
        depth_sensors = [sensor for sensor in sensors if sensor.is_depth_sensor()]
        if not depth_sensors:
            raise DeviceError("the camera has no depth sensor", self.where)
        scale = float(depth_sensors[0].as_depth_sensor().get_depth_scale())
        if not scale > 0:
            raise DeviceError(f"the camera reports a depth scale of {scale}", self.where)
        if self.depth_scale is not None and scale != self.depth_scale:
            raise DeviceError(f"this camera's depth unit is {scale:g} m, the one recorded so far "
                              f"{self.depth_scale:g} m: a different camera was plugged in (record it as another "
                              "device)", self.where)
        self.depth_scale = scale
        self.depth, self.colour = chosen[rs.stream.depth], chosen[rs.stream.color]
        self.colour_is_rgb = self.colour.profile.format() == rs.format.rgb8
        self.depth_to_colour = self.depth.profile.get_extrinsics_to(self.colour.profile)
        self._align = rs.align(rs.stream.color) if s.align_depth else None
        self._composer = _Composer(rs)
        self._frames = queue.Queue(maxsize=_QUEUE)
        self._pending: dict[Any, Any] = {rs.stream.depth: None, rs.stream.color: None}
        clock = self.context.clock
        frames = self._frames

        def arrived(frame) -> None:  # on the SDK's thread: keep the frame past the callback, hand it on
            frame.keep()
            try:
                frames.put_nowait((frame, clock.now_ns()))
            except queue.Full:  # read() is a second behind: this frame is lost (counted), as in a full USB buffer
                self._count("lost_dropped_frames")
        for i, profiles in by_sensor.items():
            sensors[i].open(profiles)
            self._sensors.append(sensors[i])
            sensors[i].start(arrived)

    def disconnect(self) -> None:
        sensors, self._sensors = self._sensors, []
        for sensor in sensors:  # a camera that was unplugged refuses both: it is gone either way
            for step in (sensor.stop, sensor.close):
                try:
                    step()
                except RuntimeError:
                    pass
        self._frames = self._align = None

    # --- reading ---

    def read(self, timeout_s: float) -> list[Sample]:
        """Frames of one instant: depth and colour paired by hardware timestamp (within half a frame), or
        one of them alone when its partner never came (counted as "unpaired_frames")."""
        if self._frames is None:
            raise DeviceError("not connected", self.where)
        rs = self._rs
        half_period_ns = 5e8 / self.settings.fps
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                frame, arrived_ns = self._frames.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                silent_s = (self.context.clock.now_ns() - self._last_frame_ns) / 1e9
                if silent_s >= self.settings.stall_timeout_s:
                    raise DeviceError(f"no frames for {silent_s:.1f} s (stall_timeout_s = "
                                      f"{self.settings.stall_timeout_s:g}): unplugged, or the USB link stalled",
                                      self.where) from None
                return []
            self._last_frame_ns = arrived_ns
            kind = frame.get_profile().stream_type()
            other_kind = rs.stream.color if kind == rs.stream.depth else rs.stream.depth
            self._check_numbering(frame)
            other = self._pending[other_kind]
            hw = self._hw_ns(frame)
            if other is not None and abs(self._hw_ns(other[0]) - hw) <= half_period_ns:
                self._pending[other_kind] = None
                pair = {kind: (frame, arrived_ns), other_kind: other}
                return self._samples(pair[rs.stream.depth], pair[rs.stream.color])
            out: list[Sample] = []
            for stale_kind in (other_kind, kind):  # a partner that can no longer come
                stale = self._pending[stale_kind]
                if stale is not None and (stale_kind == kind or self._hw_ns(stale[0]) < hw - half_period_ns):
                    self._pending[stale_kind] = None
                    self._count("unpaired_frames")
                    out += self._samples(*((stale, None) if stale_kind == rs.stream.depth else (None, stale)))
            self._pending[kind] = (frame, arrived_ns)
            if out:
                return out

    def _samples(self, depth, colour) -> list[Sample]:
        """What one instant's frames become; each argument (frame, arrival ns) or None."""
        present = [f for f in (depth, colour) if f is not None]
        first = min(present, key=lambda f: self._hw_ns(f[0]))
        offset_ns = self._offset(self._hw_ns(first[0]), first[1])
        out: list[Sample] = []
        if first[1] >= self._info_due_ns:
            out += self._info(self._hw_ns(first[0]) + offset_ns)
            self._info_due_ns = first[1] + _INFO_PERIOD_NS
        if colour is not None:
            out.append(Sample(self.image_topic, ImageSample(self._hw_ns(colour[0]) + offset_ns, self.name,
                                                            self._jpeg(colour[0]), "jpeg")))
        if depth is not None:
            frame = depth[0]
            stamp = self._hw_ns(frame) + offset_ns
            if self._align is not None:
                if colour is None:  # nothing to align to: lost to the recording, counted as unpaired
                    return out
                frame = self._align.process(self._composer.frameset(depth[0], colour[0])).get_depth_frame()
            image = np.array(np.asanyarray(frame.get_data()), dtype=np.uint16)
            out.append(Sample(self.depth_topic, DepthSample(stamp, self.depth_frame, image, self.depth_scale,
                                                            self.settings.depth_format)))
        return out

    @staticmethod
    def _hw_ns(frame) -> int:
        return int(round(frame.get_timestamp() * 1e6))  # librealsense stamps are float milliseconds

    def _offset(self, hw_ns: int, receive_ns: int) -> int:
        """Session minus hardware time for a frameset whose earliest hardware stamp is hw_ns."""
        if self._last_hw_ns is not None:
            hw_step, host_step = hw_ns - self._last_hw_ns, receive_ns - self._last_receive_ns
            period = 1e9 / self.settings.fps
            if hw_step < -period or hw_step > host_step + max(_JUMP_NS, 3 * period):
                self._count("timestamp_jumps")
                self.sync = ClockSync()  # a new clock: map it afresh rather than hold frames at the old offset
        self._last_hw_ns, self._last_receive_ns = hw_ns, receive_ns
        return self.sync.observe(hw_ns, receive_ns) - hw_ns

    def _check_numbering(self, frame) -> None:
        kind = int(frame.get_profile().stream_type())
        number = frame.get_frame_number()
        last = self._last_number.get(kind)
        if last is not None and number > last + 1:
            self._count("lost_dropped_frames", number - last - 1)
        self._last_number[kind] = number

    def _jpeg(self, frame) -> bytes:
        import cv2

        pixels = np.asanyarray(frame.get_data())
        if self.colour_is_rgb:
            pixels = pixels[:, :, ::-1]
        ok, buf = cv2.imencode(".jpg", pixels, [cv2.IMWRITE_JPEG_QUALITY, self.settings.jpeg_quality])
        if not ok:
            raise DeviceError(f"JPEG encoding failed for a {pixels.shape} frame", self.where)
        return buf.tobytes()

    def _info(self, stamp_ns: int) -> list[Sample]:
        """The depth image's calibration and the camera's frames on /tf."""
        s = self.settings
        intr = self.colour.intrinsics if self._align is not None else self.depth.intrinsics
        info = CameraInfo(stamp_ns, self.depth_frame, intr.width, intr.height,
                          (intr.fx, 0.0, intr.ppx, 0.0, intr.fy, intr.ppy, 0.0, 0.0, 1.0), tuple(intr.coeffs),
                          _DISTORTION.get(str(intr.model).split(".")[-1], "plumb_bob"))
        frames = [Transform(s.parent_frame, self.name, np.array(s.mount_xyz, float), np.array(s.mount_quat, float))]
        if self.depth_frame != self.name:  # depth in its own frame: where it sits relative to colour
            frames.append(_transform_from_extrinsics(self.name, self.depth_frame, self.depth_to_colour))
        return [Sample(self.calibration_topic, info), Sample(_TF, TransformsSample(stamp_ns, tuple(frames)))]


class _Composer:
    """Makes one frameset of a depth and a colour frame, through an SDK processing block (rs.align takes a
    frameset)."""

    def __init__(self, rs):
        self._parts: list[Any] = []
        self._out = rs.frame_queue(2)
        self._block = rs.processing_block(self._compose)
        self._block.start(self._out)

    def _compose(self, frame, source) -> None:
        source.frame_ready(source.allocate_composite_frame(self._parts))

    def frameset(self, depth, colour):
        self._parts = [depth, colour]
        self._block.invoke(depth)
        return self._out.wait_for_frame().as_frameset()


# librealsense distortion models -> foxglove.CameraCalibration's names
_DISTORTION = {"brown_conrady": "plumb_bob", "none": "plumb_bob", "inverse_brown_conrady": "plumb_bob",
               "modified_brown_conrady": "plumb_bob", "kannala_brandt4": "kannala_brandt"}


def _transform_from_extrinsics(parent: str, child: str, depth_to_colour) -> Transform:
    """child (depth) in parent (colour): the extrinsics map a depth point into colour coordinates, which is
    the pose of the depth frame in the colour frame. librealsense's rotation is column-major."""
    r = np.array(depth_to_colour.rotation, float).reshape(3, 3).T
    return Transform(parent, child, np.array(depth_to_colour.translation, float), transforms.matrix_to_quat(r))
