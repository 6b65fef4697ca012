"""How the cameras become videos: the settings a recipe or the command line gives.

The encoders that apply them live in lerobot_video.py, which imports lerobot; this module does not,
so recipes and the command line can hold video settings without that import.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

# Our codec names -> lerobot's vcodec names.
CODECS = {"h264": "h264", "hevc": "hevc", "av1": "libsvtav1"}
# What a codec gets when only the codec is chosen: (preset, crf, threads). av1 as lerobot's default.
CODEC_DEFAULTS = {"h264": ("ultrafast", 23, 1), "hevc": ("ultrafast", 28, 1), "av1": ("12", 30, 0)}


@dataclass(frozen=True)
class VideoSettings:
    codec: Literal["h264", "hevc", "av1"] = "h264"
    crf: int = 23  # quality: lower is better and larger
    preset: str = "ultrafast"  # x264/x265 preset name; for av1 an SVT-AV1 preset number ("0".."13")
    gop: int = 2  # keyframe interval: lerobot's default, so that training decodes a random frame fast
    threads: int = 1  # encoder threads per camera; 0: the codec decides
    streaming: bool = True  # encode while frames arrive (the fast path); false: lerobot writes PNGs first
    encoder: Literal["teleprev", "lerobot"] = "teleprev"  # the streaming encoder (see lerobot_video.py)
    stats_every: int = 8  # image statistics from every n-th frame (encoder = "teleprev")
    queue: int = 30  # frames buffered per camera between the exporter and the encoder thread

    def __post_init__(self):
        if self.codec not in CODECS:
            raise ValueError(f"codec must be one of {', '.join(CODECS)}, got {self.codec!r}")
        if not 0 <= self.crf <= 63:
            raise ValueError(f"crf must be 0..63, got {self.crf}")
        if self.gop < 1 or self.threads < 0 or self.stats_every < 1 or self.queue < 1:
            raise ValueError("gop, stats_every and queue must be >= 1 and threads >= 0")
        if self.codec == "av1" and not (self.preset.isdigit() and 0 <= int(self.preset) <= 13):
            raise ValueError(f"for av1 the preset is an SVT-AV1 preset number 0..13, got {self.preset!r}")

    @property
    def encoder_threads(self) -> int | None:
        return self.threads or None

    def describe(self) -> str:
        mode = f"streaming ({self.encoder} encoder)" if self.streaming else "PNG then encode"
        return f"{self.codec} crf {self.crf} preset {self.preset} gop {self.gop}, {mode}"
