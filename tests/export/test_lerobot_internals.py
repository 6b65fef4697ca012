"""The lerobot internals the exporter relies on (listed in teleprev/export/lerobot_video.py's docstring)
still have the shape it uses. After a lerobot upgrade that changes one, the test that fails names it.

lerobot is imported inside the tests, as in test_dataset.py, so that collecting the suite stays fast.
"""

import importlib.metadata
import inspect
import queue
import threading

import numpy as np
import pytest

from teleprev.export.video import CODEC_DEFAULTS, CODECS, VideoSettings

LEROBOT = importlib.metadata.version("lerobot")
DOC = "see the docstring of teleprev/export/lerobot_video.py"
HOOK = ["fps", "rgb_encoder", "depth_encoder", "encoder_queue_maxsize", "encoder_threads"]
ENCODER_STATE = {"fps": int, "queue_maxsize": int, "_episode_active": bool, "_dropped_frames": dict,
                 "_frame_queues": dict, "_result_queues": dict, "_threads": dict, "_stop_events": dict,
                 "_video_paths": dict}


def params(fn) -> list[str]:
    return [p for p in inspect.signature(fn).parameters if p not in ("self", "cls")]


def require(condition: bool, what: str) -> None:
    if not condition:
        pytest.fail(f"lerobot {LEROBOT}: {what} ({DOC})", pytrace=False)


def accepts(fn, what: str, *args, **kwargs) -> None:
    try:
        inspect.signature(fn).bind(*args, **kwargs)
    except TypeError as exc:
        pytest.fail(f"lerobot {LEROBOT}: {what} no longer accepts {sorted(kwargs)}: {exc} ({DOC})", pytrace=False)


def test_lerobot_dataset_still_builds_its_streaming_encoder_through_the_hook_we_override():
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from teleprev.export.lerobot_video import TeleprevDataset

    require(hasattr(LeRobotDataset, "_build_streaming_encoder"), "LeRobotDataset._build_streaming_encoder is gone")
    require(params(LeRobotDataset._build_streaming_encoder) == HOOK,
            f"LeRobotDataset._build_streaming_encoder takes {params(LeRobotDataset._build_streaming_encoder)}, "
            f"TeleprevDataset overrides it taking {HOOK}")
    assert params(TeleprevDataset._build_streaming_encoder) == HOOK
    for method in ("create", "resume"):
        source = inspect.getsource(getattr(LeRobotDataset, method))
        require("cls._build_streaming_encoder(" in source,
                f"LeRobotDataset.{method} no longer builds its encoder with cls._build_streaming_encoder")


def test_create_and_resume_accept_the_keywords_the_exporter_passes():
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    common = dict(video_backend="pyav", streaming_encoding=True, rgb_encoder=None, encoder_threads=1,
                  encoder_queue_maxsize=30)
    accepts(LeRobotDataset.create, "LeRobotDataset.create", repo_id="lab/x", fps=30, features={}, root="/x",
            robot_type="xarm6", use_videos=True, **common)
    accepts(LeRobotDataset.resume, "LeRobotDataset.resume", "lab/x", root="/x", **common)


def test_streaming_video_encoder_keeps_its_constructor_methods_and_state():
    from lerobot.datasets.video_utils import StreamingVideoEncoder

    from teleprev.export.lerobot_video import FastStreamingEncoder, encoder_config

    accepts(StreamingVideoEncoder, "StreamingVideoEncoder()", fps=30, rgb_encoder=None, depth_encoder=None,
            queue_maxsize=30, encoder_threads=None)
    methods = {"start_episode": ["video_keys", "temp_dir", "depth_video_keys"], "feed_frame": ["video_key", "image"],
               "finish_episode": [], "cancel_episode": [], "close": []}
    for name, expected in methods.items():
        require(callable(getattr(StreamingVideoEncoder, name, None)), f"StreamingVideoEncoder.{name} is gone")
        require(params(getattr(StreamingVideoEncoder, name)) == expected,
                f"StreamingVideoEncoder.{name} takes {params(getattr(StreamingVideoEncoder, name))}, not {expected}")
    assert params(FastStreamingEncoder.start_episode) == methods["start_episode"]

    config = encoder_config(VideoSettings())
    encoder = StreamingVideoEncoder(fps=30, rgb_encoder=config, queue_maxsize=5, encoder_threads=2)
    state = vars(encoder)
    for name, kind in ENCODER_STATE.items():
        require(isinstance(state.get(name), kind), f"StreamingVideoEncoder() no longer sets {name} ({kind.__name__})")
    require(state.get("_rgb_encoder") is config, "StreamingVideoEncoder keeps rgb_encoder no longer as _rgb_encoder")
    require(state.get("_encoder_threads") == 2,
            "StreamingVideoEncoder keeps encoder_threads no longer as _encoder_threads")
    require(encoder.queue_maxsize == 5 and encoder._episode_active is False, "StreamingVideoEncoder's state changed")


def test_lerobots_encoder_thread_speaks_the_protocol_ours_copies(tmp_path):
    """One camera through lerobot's own thread: its temporary MP4 alone in a folder of its own under
    temp_dir, named after the key, and ("ok", per-channel stats) on the result queue after None."""
    from lerobot.datasets.video_utils import StreamingVideoEncoder

    from teleprev.export.lerobot_video import encoder_config

    encoder = StreamingVideoEncoder(fps=10, rgb_encoder=encoder_config(VideoSettings()), encoder_threads=1)
    encoder.start_episode(video_keys=["observation.images.cam"], temp_dir=tmp_path, depth_video_keys=[])
    path = encoder._video_paths["observation.images.cam"]
    require(path.name == "observation.images.cam_streaming.mp4" and path.parent.parent == tmp_path,
            f"the streaming encoder's temporary file is {path.relative_to(tmp_path)}")
    require(isinstance(encoder._threads["observation.images.cam"], threading.Thread)
            and isinstance(encoder._stop_events["observation.images.cam"], threading.Event)
            and isinstance(encoder._result_queues["observation.images.cam"], queue.Queue)
            and encoder._result_queues["observation.images.cam"].maxsize == 1,
            "StreamingVideoEncoder.start_episode fills _threads/_stop_events/_result_queues differently")
    for _ in range(3):
        encoder.feed_frame("observation.images.cam", np.full((16, 24, 3), 128, np.uint8))
    results = encoder.finish_episode()
    mp4, stats = results["observation.images.cam"]
    require(mp4 == path and path.is_file(), "finish_episode no longer returns {key: (mp4 path, stats)}")
    require(set(stats) >= {"min", "max", "mean", "std", "count"} and stats["mean"].shape == (3,),
            f"the encoder thread's statistics are {({k: np.shape(v) for k, v in stats.items()})}")


def test_running_quantile_stats_gives_per_channel_statistics():
    from lerobot.datasets.compute_stats import RunningQuantileStats

    stats = RunningQuantileStats()
    stats.update(np.arange(30, dtype=np.uint8).reshape(10, 3))
    stats.update(np.arange(30, dtype=np.uint8).reshape(10, 3))
    out = stats.get_statistics()
    require(set(out) >= {"min", "max", "mean", "std", "count"}, f"RunningQuantileStats gives {sorted(out)}")
    require(all(np.shape(v) == (3,) for k, v in out.items() if k != "count"),
            "RunningQuantileStats.get_statistics() no longer gives one value per channel")


@pytest.mark.parametrize("codec", sorted(CODECS))
def test_rgb_encoder_config_takes_our_settings(codec):
    from teleprev.export.lerobot_video import encoder_config

    preset, crf, threads = CODEC_DEFAULTS[codec]
    try:
        config = encoder_config(VideoSettings(codec=codec, preset=preset, crf=crf, threads=threads))
    except (TypeError, ValueError) as exc:
        pytest.fail(f"lerobot {LEROBOT}: RGBEncoderConfig refuses our {codec} settings: {exc} ({DOC})", pytrace=False)
    require(config.vcodec == CODECS[codec], f"RGBEncoderConfig.vcodec is {config.vcodec!r}")
    require(config.pix_fmt == "yuv420p", f"RGBEncoderConfig's pixel format is {config.pix_fmt}, ours is yuv420p")
    options = config.get_codec_options(2, as_strings=True)
    require(isinstance(options, dict) and options.get("g") == "2" and all(isinstance(v, str) for v in options.values()),
            f"RGBEncoderConfig.get_codec_options(2, as_strings=True) gives {options}")


def test_the_writer_and_aggregation_pieces_dataset_and_parallel_use():
    from lerobot.datasets import dataset_writer
    from lerobot.datasets.aggregate import aggregate_datasets

    require(inspect.isfunction(getattr(dataset_writer, "embed_images", None))
            and len(params(dataset_writer.embed_images)) == 1,
            "lerobot.datasets.dataset_writer.embed_images(dataset) is gone")
    require("embed_images(" in inspect.getsource(dataset_writer.DatasetWriter),
            "DatasetWriter no longer calls the module's embed_images, so dataset.prepare_lerobot's wrapper is dead")
    require(callable(getattr(dataset_writer.DatasetWriter, "cancel_pending_videos", None))
            and params(dataset_writer.DatasetWriter.cancel_pending_videos) == [],
            "DatasetWriter.cancel_pending_videos() is gone")
    accepts(aggregate_datasets, "aggregate_datasets", repo_ids=["a"], aggr_repo_id="a", roots=["/a"], aggr_root="/b")


@pytest.mark.parametrize("choice", ["teleprev", "lerobot"])
def test_lerobot_writes_with_our_encoder_on_create_and_resume(choice, tmp_path, monkeypatch):
    """End to end through lerobot's DatasetWriter: the encoder it uses is ours, it takes our videos
    and statistics, and it leaves no temporary folder behind."""
    import datasets
    from teleprev.export import dataset as D
    from teleprev.export import lerobot_video

    monkeypatch.setenv("HF_HUB_OFFLINE", "1")
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", tmp_path / "cache")
    built = []
    original = lerobot_video.BlockingStreamingEncoder.__init__

    def recording_init(self, *args, **kwargs):
        original(self, *args, **kwargs)
        built.append(self)

    monkeypatch.setattr(lerobot_video.BlockingStreamingEncoder, "__init__", recording_init)
    settings = VideoSettings(encoder=choice, stats_every=1)
    cam = "observation.images.cam"
    features = {cam: {"dtype": "video", "shape": (16, 24, 3), "names": ["height", "width", "channels"]},
                "action": {"dtype": "float32", "shape": (2,), "names": ["a", "b"]}}
    root = tmp_path / "ds"

    def episode(ds, shade):
        for i in range(4):
            ds.add_frame({cam: np.full((16, 24, 3), shade + i, np.uint8), "action": np.zeros(2, np.float32),
                          "task": "t"})
        ds.save_episode()

    ds = D.create("lab/internals", root, 10, features, "xarm6", settings)
    episode(ds, 100)
    ds.finalize()
    ds = D.resume("lab/internals", root, settings)
    episode(ds, 200)
    ds.finalize()

    expected = lerobot_video.FastStreamingEncoder if choice == "teleprev" else lerobot_video.BlockingStreamingEncoder
    require([type(e) for e in built] == [expected, expected],
            f"LeRobotDataset.create/resume built {[type(e).__name__ for e in built]}, not our {expected.__name__}")
    assert all(e.stats_every == 1 for e in built)
    assert not [p.name for p in root.iterdir() if p.name.startswith("tmp")], "a temporary video folder is left"
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    back = LeRobotDataset("lab/internals", root=root, video_backend="pyav")
    assert back.num_episodes == 2 and back.num_frames == 8
    stats = back.meta.stats[cam]
    assert np.shape(stats["mean"]) == (3, 1, 1)
    assert 100 / 255 - 0.02 < float(np.min(stats["min"])) and float(np.max(stats["max"])) < 204 / 255 + 0.02
    frame = back[7][cam]
    assert abs(float(frame.mean()) - 203 / 255) < 0.03
