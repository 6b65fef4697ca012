"""How the cameras become videos: the settings a recipe or the command line gives, and the streaming
encoder the dataset writes its videos with.

The fast path (encoder = "teleprev", the default) plugs `FastStreamingEncoder` into lerobot's
streaming-encoding hook: lerobot still owns the episode buffer, the parquet files, the video files and
their concatenation; only the per-frame work in the encoder thread is leaner than lerobot's own:
RGB -> YUV 4:2:0 with OpenCV (BT.601 limited range, what swscale does, about 6x faster) and the image
statistics from an ~80 px copy of every `stats_every`-th frame (lerobot's own thread feeds its
histogram a ~150 px copy of every frame, which at 640x480 costs more than decoding and encoding the
frame together). What comes out is the same: an MP4 per episode and camera, and per-channel statistics
from lerobot's RunningQuantileStats. encoder = "lerobot" uses lerobot's encoder thread unchanged.
Both wait when the encoder falls behind, where lerobot's would drop frames (see feed_frame).

lerobot is imported only inside the functions below, never at module import.
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
    encoder: Literal["teleprev", "lerobot"] = "teleprev"  # the streaming encoder (see the module doc)
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

    def encoder_config(self):
        """lerobot's RGBEncoderConfig for these settings (checks that PyAV has the codec)."""
        from lerobot.configs.video import RGBEncoderConfig

        preset = int(self.preset) if self.codec == "av1" else self.preset
        return RGBEncoderConfig(vcodec=CODECS[self.codec], crf=self.crf, preset=preset, g=self.gop)

    @property
    def encoder_threads(self) -> int | None:
        return self.threads or None

    def describe(self) -> str:
        mode = f"streaming ({self.encoder} encoder)" if self.streaming else "PNG then encode"
        return f"{self.codec} crf {self.crf} preset {self.preset} gop {self.gop}, {mode}"


def encoder_classes():
    """(BlockingStreamingEncoder, FastStreamingEncoder): lerobot's StreamingVideoEncoder that waits
    instead of dropping frames, and the same with the leaner encoder thread."""
    global _CLASSES
    if _CLASSES is None:
        _CLASSES = _define_encoders()
    return _CLASSES


_CLASSES = None


def _define_encoders():
    import contextlib
    import logging
    import queue
    import shutil
    import tempfile
    import threading
    from fractions import Fraction
    from pathlib import Path

    import av
    import cv2
    import numpy as np
    from lerobot.datasets.compute_stats import RunningQuantileStats
    from lerobot.datasets.video_utils import StreamingVideoEncoder

    log = logging.getLogger(__name__)

    class _EncoderThread(threading.Thread):
        """One camera of one episode: RGB frames from a queue into an MP4, plus image statistics.
        Speaks the protocol of lerobot's _CameraEncoderThread: None ends the stream, the result queue
        receives ("ok", stats | None) or ("error", message)."""

        def __init__(self, path: Path, fps: int, config, frames: queue.Queue, results: queue.Queue,
                     stop: threading.Event, threads: int | None, stats_every: int):
            super().__init__(daemon=True, name=f"encode-{path.stem}")
            self.path, self.fps, self.config = path, fps, config
            self.frames, self.results, self.stop = frames, results, stop
            self.threads, self.stats_every = threads, stats_every

        def run(self) -> None:
            container = stream = None
            stats = RunningQuantileStats()
            count = sampled = 0
            try:
                while True:
                    try:
                        image = self.frames.get(timeout=1)
                    except queue.Empty:
                        if self.stop.is_set():
                            break
                        continue
                    if image is None:
                        break
                    if image.ndim == 3 and image.shape[0] == 3 and image.shape[2] != 3:
                        image = image.transpose(1, 2, 0)
                    if image.dtype != np.uint8:
                        image = (image * 255).astype(np.uint8)
                    height, width = image.shape[:2]
                    if container is None:
                        if height % 2 or width % 2:
                            raise ValueError(f"frames of {width}x{height}: YUV 4:2:0 needs even sizes")
                        container = av.open(str(self.path), "w")
                        stream = container.add_stream(self.config.vcodec, self.fps, options=self.config.get_codec_options(
                            self.threads, as_strings=True))
                        stream.pix_fmt = self.config.pix_fmt
                        stream.width, stream.height = width, height
                        stream.time_base = Fraction(1, self.fps)
                    yuv = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2YUV_I420)
                    frame = av.VideoFrame.from_ndarray(yuv, format="yuv420p")
                    frame.pts = count
                    frame.time_base = Fraction(1, self.fps)
                    for packet in stream.encode(frame):
                        container.mux(packet)
                    if count % self.stats_every == 0:
                        # ~80 px across: per-channel pixel statistics need no more, and lerobot's
                        # histogram update costs ~4 ms at its own ~150 px
                        step = max(1, max(height, width) // 80)
                        stats.update(image[::step, ::step].reshape(-1, image.shape[2]))
                        sampled += 1
                    count += 1
                if stream is not None:
                    for packet in stream.encode():
                        container.mux(packet)
                if container is not None:
                    container.close()
                    container = None
                self.results.put(("ok", stats.get_statistics() if sampled >= 2 else None))
            except Exception as exc:  # reported to the exporter through the result queue
                log.error("encoder thread for %s failed: %s", self.path.name, exc)
                if container is not None:
                    with contextlib.suppress(Exception):
                        container.close()
                self.results.put(("error", str(exc)))

    class BlockingStreamingEncoder(StreamingVideoEncoder):
        """lerobot's StreamingVideoEncoder, except that a full queue waits instead of dropping."""

        def feed_frame(self, video_key, image):
            # lerobot's feed_frame drops a frame when the queue stays full for 0.1 s (right for a live
            # recording); an export is faster than the encoder and must not lose frames, so it waits
            # for the encoder thread (and notices when that died).
            if not self._episode_active:
                raise RuntimeError("No active episode. Call start_episode() first.")
            thread = self._threads[video_key]
            frame = image.copy()
            while True:
                if not thread.is_alive():
                    try:
                        status, message = self._result_queues[video_key].get_nowait()
                    except queue.Empty:
                        status, message = "error", "stopped"
                    raise RuntimeError(f"the video encoder for {video_key} failed: {message}")
                try:
                    self._frame_queues[video_key].put(frame, timeout=0.5)
                    return
                except queue.Full:
                    continue

        def cancel_episode(self):
            paths = list(self._video_paths.values())
            super().cancel_episode()
            for path in paths:  # lerobot only removes the folder when the file exists
                shutil.rmtree(path.parent, ignore_errors=True)

    class FastStreamingEncoder(BlockingStreamingEncoder):
        """The same queues, finish/cancel and results, with _EncoderThread doing the work."""

        stats_every = 8

        def start_episode(self, video_keys, temp_dir, depth_video_keys=None):
            if depth_video_keys:
                raise ValueError("the teleprev encoder does not encode depth cameras; use encoder = \"lerobot\"")
            if self._episode_active:
                self.cancel_episode()
            self._dropped_frames.clear()
            for key in video_keys:
                frames: queue.Queue = queue.Queue(maxsize=self.queue_maxsize)
                results: queue.Queue = queue.Queue(maxsize=1)
                stop = threading.Event()
                path = Path(tempfile.mkdtemp(dir=temp_dir)) / f"{key.replace('/', '_')}_streaming.mp4"
                thread = _EncoderThread(path, self.fps, self._rgb_encoder, frames, results, stop,
                                        self._encoder_threads, self.stats_every)
                thread.start()
                self._frame_queues[key] = frames
                self._result_queues[key] = results
                self._threads[key] = thread
                self._stop_events[key] = stop
                self._video_paths[key] = path
            self._episode_active = True

    return BlockingStreamingEncoder, FastStreamingEncoder


def dataset_class(settings: VideoSettings):
    """LeRobotDataset whose streaming encoder (when streaming is on) is one of ours."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    blocking, fast = encoder_classes()
    cls = fast if settings.encoder == "teleprev" else blocking

    class TeleprevDataset(LeRobotDataset):
        @staticmethod
        def _build_streaming_encoder(fps, rgb_encoder, depth_encoder, encoder_queue_maxsize, encoder_threads):
            encoder = cls(fps=fps, rgb_encoder=rgb_encoder, depth_encoder=depth_encoder,
                          queue_maxsize=encoder_queue_maxsize, encoder_threads=encoder_threads)
            encoder.stats_every = settings.stats_every
            return encoder

    return TeleprevDataset
