"""The streaming video encoders the exporter plugs into lerobot's LeRobotDataset.

Importing this module imports lerobot (about 15 s), so only the code that writes a dataset imports it,
inside a function (teleprev/export/dataset.py).

`FastStreamingEncoder` (encoder = "teleprev", the default) keeps lerobot's episode buffer, parquet
files, video files and their concatenation; only the per-frame work in the encoder thread is leaner:
RGB -> YUV 4:2:0 with OpenCV (BT.601 limited range, what swscale does, about 6x faster) and image
statistics from an ~80 px copy of every `stats_every`-th frame (lerobot's own thread feeds its
histogram a ~150 px copy of every frame, which at 640x480 costs more than decoding and encoding the
frame together). The output is the same: an MP4 per episode and camera, and per-channel statistics
from lerobot's RunningQuantileStats. `BlockingStreamingEncoder` (encoder = "lerobot") is lerobot's
encoder unchanged except that both wait when the encoder falls behind, where lerobot's drops frames.

lerobot internals this module relies on, as of lerobot 0.6.1 (tests/export/test_lerobot_internals.py
checks each one, so an upgrade that changes them fails there rather than in an export):

lerobot.datasets.lerobot_dataset.LeRobotDataset
  - `_build_streaming_encoder(fps, rgb_encoder, depth_encoder, encoder_queue_maxsize, encoder_threads)`,
    a private static hook that create(), resume() (and the deprecated write mode of __init__) call,
    positionally, to build the encoder when streaming_encoding is on and the dataset has video keys.
    TeleprevDataset overrides it.
lerobot.datasets.video_utils.StreamingVideoEncoder (not in lerobot's documentation)
  - constructor keywords fps, rgb_encoder, depth_encoder, queue_maxsize, encoder_threads;
  - start_episode(video_keys, temp_dir, depth_video_keys), which FastStreamingEncoder calls for the depth
    keys alone: it starts lerobot's own encoder thread for each (quantisation, 12-bit lossless HEVC), ends an
    active episode, clears _dropped_frames and sets _episode_active;
  - the methods lerobot's DatasetWriter calls: start_episode(video_keys=, temp_dir=, depth_video_keys=)
    on an episode's first frame, feed_frame(video_key, image), finish_episode() returning
    {video key: (mp4 path, stats or None)}, cancel_episode() and close();
  - the private state its methods share, which we read and fill: fps, queue_maxsize, _rgb_encoder,
    _encoder_threads, _episode_active, _dropped_frames, and the per-video-key dicts _frame_queues,
    _result_queues, _threads, _stop_events, _video_paths;
  - the encoder-thread protocol of its _CameraEncoderThread, which _EncoderThread speaks: the frame
    queue carries HWC or CHW images and None to end the stream, a set stop event ends it early,
    and the one-slot result queue receives ("ok", stats or None) or ("error", message);
  - the file layout: every camera's temporary MP4 alone in its own tempfile.mkdtemp(dir=temp_dir)
    folder, named "<key with / as _>_streaming.mp4"; DatasetWriter._save_episode_video removes that
    folder after taking the file, and cancel_episode removes it only when the file exists.
lerobot.datasets.compute_stats.RunningQuantileStats
  - update(array of shape (pixels, channels)) and get_statistics() -> {name: per-channel array,
    "count": array}, which DatasetWriter.save_episode reshapes to (channels, 1, 1) and divides by 255.
lerobot.configs.video.RGBEncoderConfig
  - constructor keywords vcodec, crf, preset, g; attributes vcodec and pix_fmt (which must stay
    "yuv420p": the frames are converted to I420 here); get_codec_options(encoder_threads, as_strings=True).

The rest of the exporter's lerobot contact, checked by the same test: LeRobotDataset.create/resume with
the keywords dataset.py passes, lerobot.datasets.dataset_writer.embed_images (a module global that
dataset.py replaces), DatasetWriter.cancel_pending_videos(), and aggregate_datasets(repo_ids,
aggr_repo_id, roots, aggr_root) in parallel.py.
"""

from __future__ import annotations

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
from lerobot.configs.video import RGBEncoderConfig
from lerobot.datasets.compute_stats import RunningQuantileStats
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.video_utils import StreamingVideoEncoder

from teleprev.export.video import CODECS, VideoSettings

log = logging.getLogger(__name__)


def encoder_config(settings: VideoSettings) -> RGBEncoderConfig:
    """lerobot's RGBEncoderConfig for these settings (it checks that PyAV has the codec)."""
    preset = int(settings.preset) if settings.codec == "av1" else settings.preset
    return RGBEncoderConfig(vcodec=CODECS[settings.codec], crf=settings.crf, preset=preset, g=settings.gop)


class _EncoderThread(threading.Thread):
    """One camera of one episode: RGB frames from a queue into an MP4, plus image statistics.
    Speaks the protocol of lerobot's _CameraEncoderThread (see the module doc)."""

    def __init__(self, path: Path, fps: int, config: RGBEncoderConfig, frames: queue.Queue, results: queue.Queue,
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
                    container, stream = self._open(width, height)
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
            log.debug("encoder thread for %s failed: %s", self.path.name, exc)  # the export says it, once
            if container is not None:
                with contextlib.suppress(Exception):
                    container.close()
            self.results.put(("error", str(exc)))

    def _open(self, width: int, height: int):
        if height % 2 or width % 2:
            raise ValueError(f"frames of {width}x{height}: YUV 4:2:0 needs even sizes")
        container = av.open(str(self.path), "w")
        options = self.config.get_codec_options(self.threads, as_strings=True)
        stream = container.add_stream(self.config.vcodec, self.fps, options=options)
        stream.pix_fmt = self.config.pix_fmt
        stream.width, stream.height = width, height
        stream.time_base = Fraction(1, self.fps)
        return container, stream


class BlockingStreamingEncoder(StreamingVideoEncoder):
    """lerobot's StreamingVideoEncoder, except that a full queue waits instead of dropping."""

    stats_every = 8  # used by FastStreamingEncoder; set on both so the dataset need not tell them apart

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
                    _, message = self._result_queues[video_key].get_nowait()
                except queue.Empty:
                    message = "stopped"
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

    def start_episode(self, video_keys, temp_dir, depth_video_keys=None):
        # Depth maps go to lerobot's own encoder thread: its 12-bit log quantisation and lossless HEVC are
        # the convention LeRobotDataset reads back (it also ends an active episode and clears the drops).
        depth = [key for key in video_keys if key in (depth_video_keys or ())]
        StreamingVideoEncoder.start_episode(self, depth, temp_dir, depth)
        for key in video_keys:
            if key in depth:
                continue
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


class TeleprevDataset(LeRobotDataset):
    """LeRobotDataset whose streaming encoder is one of ours. Write with `for_settings(settings)`: the
    choice of encoder rides on the class because lerobot builds the encoder before any instance exists."""

    encoder_class: type[BlockingStreamingEncoder] = FastStreamingEncoder
    stats_every = 8

    @classmethod
    def for_settings(cls, settings: VideoSettings) -> type[TeleprevDataset]:
        encoder = FastStreamingEncoder if settings.encoder == "teleprev" else BlockingStreamingEncoder
        return type(cls.__name__, (cls,), {"encoder_class": encoder, "stats_every": settings.stats_every})

    @classmethod
    def _build_streaming_encoder(cls, fps, rgb_encoder, depth_encoder, encoder_queue_maxsize, encoder_threads):
        encoder = cls.encoder_class(fps=fps, rgb_encoder=rgb_encoder, depth_encoder=depth_encoder,
                                    queue_maxsize=encoder_queue_maxsize, encoder_threads=encoder_threads)
        encoder.stats_every = cls.stats_every
        return encoder
