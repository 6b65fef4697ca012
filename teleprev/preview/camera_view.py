"""A camera frame as a small colour picture in the terminal: each cell is two pixels, the upper half block
"▀" in the upper pixel's colour on the lower pixel's. Operators watch the scene, so the preview shows it.

A depth frame (a DepthSample) is shown colour-mapped: near red, far blue (OpenCV's TURBO map, reversed), spread
over the frame's own range of depths (its 2nd to 98th percentile, so that a stray return does not flatten the
rest), and black where the camera saw nothing (0).

Frames arrive compressed (JPEG/PNG); one is decoded at a quarter of its size (libjpeg scales while it
decodes, so a 640x480 frame costs about a millisecond) and only when a newer frame is shown.
"""

from __future__ import annotations

import functools

import numpy as np
from rich.style import Style
from rich.text import Text

HALF = "▀"


class _FrameView:
    """The latest frame of a stream as RGB, converted (`_to_rgb`) once per new frame."""

    what = "frame"  # "no <what> frame yet" until one arrives

    def __init__(self) -> None:
        self._stamp: int | None = None
        self._rgb: np.ndarray | None = None

    def rgb(self, sample) -> np.ndarray | None:
        if sample is None:
            return None
        if sample.stamp_ns != self._stamp:
            self._rgb, self._stamp = self._to_rgb(sample), sample.stamp_ns
        return self._rgb

    def _to_rgb(self, sample) -> np.ndarray | None:
        raise NotImplementedError

    def render(self, sample, cols: int, rows: int):
        rgb = self.rgb(sample)
        if rgb is None:
            return Text(f"no {self.what} frame yet", style="dim")
        return picture(rgb, cols, rows)


class CameraView(_FrameView):
    """The latest ImageSample as RGB (decoded at a quarter size; None if it does not decode)."""

    what = "camera"

    def _to_rgb(self, sample) -> np.ndarray | None:
        if getattr(sample, "format", "jpeg") == "raw":
            return np.asarray(sample.data)
        import cv2

        bgr = cv2.imdecode(np.frombuffer(sample.data, np.uint8), cv2.IMREAD_REDUCED_COLOR_4)
        return None if bgr is None else bgr[:, :, ::-1]


class DepthView(_FrameView):
    """The latest depth frame, colour-mapped (depth_rgb)."""

    what = "depth"

    def _to_rgb(self, sample) -> np.ndarray:
        return depth_rgb(sample.metres())


LEVELS = (32, 232)  # the part of OpenCV's TURBO colour map that depths are spread over, far to near
DEPTH_STEP = 4  # a depth frame is colour-mapped at a quarter of its size, as colour frames are decoded


def depth_rgb(metres: np.ndarray, step: int = DEPTH_STEP) -> np.ndarray:
    """(H/step, W/step, 3) uint8 RGB of a depth image in metres: near red, far blue, 0 (no return) black."""
    small = np.ascontiguousarray(metres[::step, ::step], dtype=np.float32)
    seen = small > 0
    if not seen.any():
        return np.zeros((*small.shape, 3), np.uint8)
    near, far = np.percentile(small[seen], (2, 98))
    scaled = np.clip((small - near) / max(float(far - near), 1e-6), 0.0, 1.0)
    # TURBO runs blue -> red (near gets the red end); its darkest ends are left out, unreadable on a terminal
    levels = np.rint(LEVELS[0] + (LEVELS[1] - LEVELS[0]) * (1.0 - scaled)).astype(np.uint8)
    rgb = _turbo()[levels]
    rgb[~seen] = 0
    return rgb


@functools.cache
def _turbo() -> np.ndarray:
    """OpenCV's TURBO colour map as a (256, 3) RGB table: cv2.applyColorMap builds it again on every call
    (50 ms on a busy machine), indexing it costs a fraction of a millisecond."""
    import cv2

    table = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_TURBO)  # (256, 1, 3) BGR
    return np.ascontiguousarray(table[:, 0, ::-1])


def fit(height: int, width: int, cols: int, rows: int) -> tuple[int, int]:
    """(cols, rows) of the largest picture of that aspect in cols x rows cells (a cell is two pixels high)."""
    scale = min(cols / width, 2 * rows / height)
    return max(1, int(width * scale)), max(1, int(height * scale / 2))


class Picture:
    """`rows` lines of `cols` half blocks, each with its two pixels' colours (quantized to 5 bits a channel,
    so that neighbouring cells share Style objects and runs of equal cells print as one segment)."""

    _styles: dict[bytes, Style] = {}

    def __init__(self, top: np.ndarray, bottom: np.ndarray):
        self.top, self.bottom = top & 0xF8, bottom & 0xF8

    def __rich_console__(self, console, options):
        from rich.color import Color
        from rich.segment import Segment

        rows, cols = self.top.shape[:2]
        cells = np.concatenate([self.top, self.bottom], axis=2).reshape(rows, cols, 6)
        for r in range(rows):
            line = cells[r]
            same = np.r_[False, (line[1:] == line[:-1]).all(axis=1)]
            starts = np.flatnonzero(~same).tolist() + [cols]
            for a, b in zip(starts[:-1], starts[1:]):
                key = line[a].tobytes()
                style = self._styles.get(key)
                if style is None:
                    t, u = line[a][:3].tolist(), line[a][3:].tolist()
                    style = self._styles[key] = Style(color=Color.from_rgb(*t), bgcolor=Color.from_rgb(*u))
                yield Segment(HALF * (b - a), style)
            yield Segment.line()

    def __rich_measure__(self, console, options):
        from rich.measure import Measurement

        return Measurement(self.top.shape[1], self.top.shape[1])


def picture(rgb: np.ndarray, cols: int, rows: int) -> Picture:
    import cv2

    w, h = fit(rgb.shape[0], rgb.shape[1], cols, rows)
    small = cv2.resize(np.ascontiguousarray(rgb), (w, 2 * h), interpolation=cv2.INTER_AREA)
    return Picture(small[0::2], small[1::2])
