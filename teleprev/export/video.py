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


# The encoders' own ranges: x264 and x265 take a crf of 0..51, SVT-AV1 0..63; their presets by name.
MAX_CRF = {"h264": 51, "hevc": 51, "av1": 63}
X26X_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow",
                "placebo")
MAX_GOP = 1000  # frames between keyframes: past this a training sampler decodes for seconds to reach a frame
ENCODERS = ("teleprev", "lerobot")


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
        """Every value checked here, where a recipe's [video] table and the command line both pass: an
        encoder that refuses one does so only after the frames of an episode are read (a traceback then)."""
        if self.codec not in CODECS:
            raise ValueError(f"codec must be one of {', '.join(CODECS)}, got {self.codec!r}")
        top = MAX_CRF[self.codec]
        if not 0 <= self.crf <= top:
            raise ValueError(f"crf must be 0..{top} for {self.codec}, got {self.crf}")
        if not 1 <= self.gop <= MAX_GOP:
            raise ValueError(f"gop (the keyframe interval, in frames) must be 1..{MAX_GOP}, got {self.gop}")
        if self.threads < 0 or self.stats_every < 1 or self.queue < 1:
            raise ValueError("stats_every and queue must be >= 1 and threads >= 0")
        if self.codec == "av1" and not (self.preset.isdigit() and 0 <= int(self.preset) <= 13):
            raise ValueError(f"for av1 the preset is an SVT-AV1 preset number 0..13, got {self.preset!r}")
        if self.codec != "av1" and self.preset not in X26X_PRESETS:
            raise ValueError(f"for {self.codec} the preset is one of {', '.join(X26X_PRESETS)}, got {self.preset!r}")
        if self.encoder not in ENCODERS:
            raise ValueError(f"encoder must be {' or '.join(ENCODERS)}, got {self.encoder!r}")

    @property
    def encoder_threads(self) -> int | None:
        return self.threads or None

    def describe(self) -> str:
        mode = f"streaming ({self.encoder} encoder)" if self.streaming else "PNG then encode"
        return f"{self.codec} crf {self.crf} preset {self.preset} gop {self.gop}, {mode}"
