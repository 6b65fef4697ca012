"""opencv.camera: a camera by index, a video file or a stream URL, read with cv2.VideoCapture and
published as JPEG on /camera/<name>/image.

    [devices.cam_wrist]
    plugin = "opencv.camera"
    source = 0                 # camera index, or "clips/table.mp4" (relative to the rig file), or "rtsp://..."
    width = 640                # 0: as delivered; otherwise frames are requested and, if need be, resized
    height = 480
    fps = 30.0                 # camera: requested rate; file: 0 plays at the file's own rate
    jpeg_quality = 85
    loop = false               # file: start over at the end (otherwise the stream ends: a gap)
    stall_timeout_s = 1.0      # stream URL: no frame for this long is a stall

A live frame is stamped when read() got it from the driver; a file's frames are paced at their rate on
the session clock and stamped at their due time. A network stream (rtsp://, http:// MJPEG, ...) that
stalls for stall_timeout_s, or that the server ends, is a device error naming which; the runner then
opens it again every reconnect period, so the camera comes back with the server.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from teleprev.devices import Device, DeviceContext, DeviceError, ImageSample, Sample, StreamSpec, wait_until_due

_DEFAULT_FPS = 30.0


@dataclass
class OpenCVSettings:
    source: int | str = 0
    width: int = 0
    height: int = 0
    fps: float = 0.0  # 0: the file's rate, or the camera's default (nominally 30)
    jpeg_quality: int = 85
    loop: bool = False
    stall_timeout_s: float = 1.0

    def __post_init__(self):
        if isinstance(self.source, int) and self.source < 0:
            raise ValueError(f"source must be a camera index >= 0, a file or a URL, got {self.source}")
        if isinstance(self.source, str) and not self.source.strip():
            raise ValueError("source must not be empty")
        if (self.width == 0) != (self.height == 0) or not (
            self.width == 0 or 16 <= self.width <= 8192 and 16 <= self.height <= 8192
        ):
            raise ValueError(
                f"width and height must both be 0 (as delivered) or 16..8192, got {self.width}x{self.height}"
            )
        if not 0 <= self.fps <= 1000:
            raise ValueError(f"fps must be 0..1000, got {self.fps}")
        if not 0.05 <= self.stall_timeout_s <= 60:
            raise ValueError(f"stall_timeout_s must be 0.05..60, got {self.stall_timeout_s}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be 1..100, got {self.jpeg_quality}")


class OpenCVCamera(Device[OpenCVSettings], kind="camera"):
    """ImageSample (JPEG) on /camera/<name>/image, frame_id = the device name."""

    def __init__(self, name: str, settings: OpenCVSettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.image_topic = self.topic("image")
        src = settings.source
        self.is_camera = isinstance(src, int)
        self.is_url = isinstance(src, str) and "://" in src
        self.path = None if self.is_camera or self.is_url else _resolve(context.rig_dir, src)
        self.where = f"device {name!r} (camera {src})" if self.is_camera else f"device {name!r} ({src})"
        self._cap = None
        self._ended = False
        self._failed_reads = 0

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.image_topic, "image", self.settings.fps or self._file_fps() or _DEFAULT_FPS)]

    def endpoint(self) -> str:
        return f"camera {self.settings.source}" if self.is_camera else str(self.settings.source)

    def _file_fps(self) -> float:
        if self.path is None or not self.path.is_file():
            return 0.0
        import cv2

        cap = cv2.VideoCapture(str(self.path))
        fps = cap.get(cv2.CAP_PROP_FPS) if cap.isOpened() else 0.0
        cap.release()
        return fps if 0 < fps <= 1000 else 0.0

    def connect(self) -> None:
        import cv2

        s = self.settings
        if self.path is not None and not self.path.is_file():
            raise DeviceError(f"no such video file: {self.path}", self.where)
        if self.is_url:  # bounded waits: a stream that stalls must not hold the reader forever
            timeout_ms = int(s.stall_timeout_s * 1000)
            cap = cv2.VideoCapture(s.source, cv2.CAP_FFMPEG, [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, max(timeout_ms, 2000),
                                                              cv2.CAP_PROP_READ_TIMEOUT_MSEC, timeout_ms])
        else:
            cap = cv2.VideoCapture(s.source if self.is_camera else str(self.path or s.source))
        if not cap.isOpened():
            cap.release()
            what = (
                f"camera index {s.source}"
                if self.is_camera
                else (f"stream {s.source}" if self.is_url else f"video file {self.path}")
            )
            raise DeviceError(f"cannot open {what} (unplugged, in use, or not a format OpenCV reads)", self.where)
        if self.is_camera or self.is_url:
            if s.width:
                cap.set(cv2.CAP_PROP_FRAME_WIDTH, s.width)
                cap.set(cv2.CAP_PROP_FRAME_HEIGHT, s.height)
            if s.fps:
                cap.set(cv2.CAP_PROP_FPS, s.fps)
            self.period_ns = 0  # the driver paces a live source
        else:
            file_fps = cap.get(cv2.CAP_PROP_FPS)
            self.period_ns = int(round(1e9 / (s.fps or (file_fps if 0 < file_fps <= 1000 else _DEFAULT_FPS))))
        self._cap = cap
        self._ended = False
        self._failed_reads = 0
        self._next_ns = self.context.clock.now_ns()

    def disconnect(self) -> None:
        cap, self._cap = self._cap, None
        if cap is not None:
            cap.release()

    def read(self, timeout_s: float) -> list[Sample]:
        if self._cap is None:
            raise DeviceError("not connected", self.where)
        clock = self.context.clock
        if self.period_ns:  # a file: wait until the next frame is due
            if self._ended:
                time.sleep(timeout_s)
                return []
            if not wait_until_due(clock, self._next_ns, timeout_s):
                return []
        asked = time.monotonic()
        ok, frame = self._cap.read()
        stamp = self._next_ns if self.period_ns else clock.now_ns()
        if not ok or frame is None:
            if self.is_url:  # FFmpeg gives up on the stream after a stall or its end: open it again
                waited = time.monotonic() - asked
                if waited >= 0.9 * self.settings.stall_timeout_s:
                    raise DeviceError(f"the stream stalled: no frame for {waited:.1f} s (stall_timeout_s = "
                                      f"{self.settings.stall_timeout_s:g})", self.where)
                raise DeviceError("the stream ended (the server closed it)", self.where)
            return self._no_frame()
        self._failed_reads = 0
        if self.period_ns:
            # Pace from the due time, not from when we got here, so the file keeps its rate; after a
            # long stall start again from now rather than bursting to catch up.
            self._next_ns = max(self._next_ns + self.period_ns, clock.now_ns() - 5 * self.period_ns)
        return [Sample(self.image_topic, ImageSample(stamp, self.name, self._encode(frame), "jpeg"))]

    def _no_frame(self) -> list[Sample]:
        import cv2

        if self.path is not None:
            if self.settings.loop:  # reopening works for every container, seeking does not
                self._cap.release()
                self._cap = cv2.VideoCapture(str(self.path))
                if not self._cap.isOpened():
                    raise DeviceError(f"cannot reopen video file {self.path}", self.where)
                return []
            self._ended = True  # the file is over: no more samples (the runner shows a gap)
            return []
        self._failed_reads += 1
        if self._failed_reads >= 3:
            raise DeviceError("stopped delivering frames (unplugged or stream ended)", self.where)
        return []

    def _encode(self, frame) -> bytes:
        import cv2

        s = self.settings
        if s.width and (frame.shape[1] != s.width or frame.shape[0] != s.height):
            frame = cv2.resize(frame, (s.width, s.height), interpolation=cv2.INTER_AREA)
        ok, buf = cv2.imencode(".jpg", frame, [cv2.IMWRITE_JPEG_QUALITY, s.jpeg_quality])
        if not ok:
            raise DeviceError(f"JPEG encoding failed for a {frame.shape} frame", self.where)
        return buf.tobytes()


def _resolve(rig_dir: Path, source: str) -> Path:
    p = Path(source).expanduser()
    return p if p.is_absolute() else Path(rig_dir) / p
