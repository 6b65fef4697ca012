"""`teleprev export` end to end: real MCAP sessions (written with the session writer, content known
exactly) exported into real LeRobot v3.0 datasets, read back with lerobot's own LeRobotDataset and
DataLoader, their videos decoded with PyAV.

Expected values are worked out from the source session alone: every synthetic camera frame carries
its frame number as black and white blocks, so a decoded dataset frame says which recorded frame it
is, hence its time; the state must be the latest recorded sample at or before that time, and the action
the commanded trajectory at the frame's grid time (the episode's first frame + its index / fps: the
dataset's own timestamp), between the commands sent around it (or, with the sent_commands recipe, the
first command sent at or after the frame's time).
"""

import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from teleprev.errors import ConfigError, SessionError
from teleprev.export.recipe import load_recipe
from teleprev.export.run import ExportOptions, export
from teleprev.export.synthetic import EpisodeSpec, SyntheticSession, read_frame_code, write_session
from teleprev.messages import ImageSample, Logged
from teleprev.session.reader import SessionReader
from teleprev.session.writer import McapSessionWriter

FPS = 30
CAM = "observation.images.cam_front"
ARM = "/arm/arm/state"
HAND = "/hand/hand/state"


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    d = tmp_path_factory.mktemp("sessions")
    return SimpleNamespace(
        dir=d,
        a=write_session(
            d / "a.mcap",
            SyntheticSession((EpisodeSpec("pick_place", 2.0), EpisodeSpec("pour", 1.5, outcome="success")), seed=1),
        ),
        b=write_session(
            d / "b.mcap",
            SyntheticSession(
                (EpisodeSpec("hang", 2.0), EpisodeSpec("hang", 1.0, discarded=True), EpisodeSpec("cup_stack", 2.0)),
                seed=2,
            ),
        ),
        # a 0.4 s camera gap in the first episode; the second is in preview (no commands) for 0.5 s
        c=write_session(
            d / "c.mcap",
            SyntheticSession(
                (
                    EpisodeSpec("pour", 2.0, camera_gaps=((0.8, 1.2),)),
                    EpisodeSpec("box_rotation", 2.0, commands_after_s=0.5),
                ),
                seed=3,
            ),
        ),
    )


def load(repo_id, root, **kw):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    return LeRobotDataset(repo_id, root=root, video_backend="pyav", **kw)


def leftovers(root: Path) -> list[str]:
    """Staging folders an export left beside its target."""
    return sorted(p.name for p in root.parent.glob(f".{root.name}.export-*"))


class Source:
    """A session read back independently of the exporter: joint streams and camera frames by number."""

    def __init__(self, path):
        with SessionReader(path) as r:
            self.episodes = r.episodes()
            self.streams = {}
            for topic in (ARM, HAND, "/command/arm", "/command/hand"):
                msgs = [m.payload for m in r.messages([topic])]
                self.streams[topic] = (np.array([p.stamp_ns for p in msgs]), np.array([p.positions for p in msgs]))
            self.frames = {}
            for m in r.messages(["/camera/cam_front/image"]):
                rgb = cv2.imdecode(np.frombuffer(m.payload.data, np.uint8), cv2.IMREAD_COLOR_RGB)
                self.frames[read_frame_code(rgb)] = (m.payload.stamp_ns, rgb)

    def latest(self, topic, t):
        stamps, values = self.streams[topic]
        i = np.searchsorted(stamps, t, side="right") - 1
        assert i >= 0
        return values[i], t - stamps[i]

    def trajectory(self, topic, g):
        """The commands at time g: straight between the two around it (commands without velocities) when
        they are at most 100 ms apart, else the last one before it (held)."""
        stamps, values = self.streams[topic]
        i = np.searchsorted(stamps, g, side="right") - 1
        assert i >= 0
        if i + 1 < len(stamps) and stamps[i + 1] - stamps[i] <= 100_000_000:
            s = (g - stamps[i]) / (stamps[i + 1] - stamps[i])
            return values[i] + s * (values[i + 1] - values[i]), min(g - stamps[i], stamps[i + 1] - g)
        return values[i], g - stamps[i]

    def command(self, topic, t, t_next):
        """The first command sent in [t, t_next); if none, the last one before t (the robot holds it)."""
        stamps, values = self.streams[topic]
        i = np.searchsorted(stamps, t, side="left")
        if i < len(stamps) and stamps[i] < t_next:
            return values[i], stamps[i] - t
        return values[i - 1], t - stamps[i - 1]


def psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(float) - b.astype(float)) ** 2)
    return np.inf if mse == 0 else 10 * np.log10(255.0**2 / mse)


@pytest.fixture(scope="module")
def exported_a(sessions, tmp_path_factory):
    root = tmp_path_factory.mktemp("out") / "lab" / "a"
    report = export(ExportOptions([sessions.a], "lab/a", root, load_recipe()))
    return root, report


def test_a_session_loads_back_with_its_episodes_features_tasks_values_and_images(sessions, exported_a):
    root, report = exported_a
    assert leftovers(root) == []
    ds = load("lab/a", root)
    src = Source(sessions.a)
    assert ds.num_episodes == 2 and ds.fps == FPS
    assert ds.meta.robot_type == "xarm6_leap_hand"
    state_names = [f"arm.joint{i}" for i in range(1, 7)] + [f"hand.{i}" for i in range(16)]
    for key in ("observation.state", "action"):
        assert ds.features[key]["dtype"] == "float32"
        assert tuple(ds.features[key]["shape"]) == (22,)
        assert ds.features[key]["names"] == state_names
    assert ds.features[CAM]["dtype"] == "video" and tuple(ds.features[CAM]["shape"]) == (240, 320, 3)
    assert ds.meta.info.features[CAM]["info"]["video.codec"] == "h264"
    lengths = [int(n) for n in ds.meta.episodes["length"]]
    assert ds.num_frames == sum(lengths) == report.frames
    for n, ep in zip(lengths, src.episodes):  # every camera frame of the episode, one frame each
        assert abs(n - (ep.stop_ns - ep.start_ns) * FPS / 1e9) <= 1.5

    # every frame's image, decoded with lerobot's decoder (one call per episode, as training reads them)
    from lerobot.datasets.video_utils import decode_video_frames

    rows = ds.hf_dataset.with_format("numpy")[:]
    images = []
    for e, ep in enumerate(ds.meta.episodes):
        t0 = float(ep[f"videos/{CAM}/from_timestamp"])
        ts = [t0 + k / FPS for k in range(int(ep["length"]))]
        frames = decode_video_frames(
            root / ds.meta.get_video_file_path(e, CAM), ts, 1e-4, backend="pyav", return_uint8=True
        )
        images.extend(frames.permute(0, 2, 3, 1).numpy())
    assert len(images) == len(ds)
    numbers = [read_frame_code(img) for img in images]
    first_stamp = {}  # per episode: its first frame's camera time, where its frame grid starts
    for i in range(len(ds)):
        first_stamp.setdefault(int(rows["episode_index"][i]), src.frames[numbers[i]][0])
    worst_err, worst_psnr = 0, np.inf
    for i in range(len(ds)):
        e = int(rows["episode_index"][i])
        assert ds.meta.tasks.index[int(rows["task_index"][i])] == src.episodes[e].task
        assert float(rows["timestamp"][i]) == pytest.approx(int(rows["frame_index"][i]) / FPS, abs=1e-6)
        stamp, source_rgb = src.frames[numbers[i]]
        last = i + 1 == len(ds) or int(rows["episode_index"][i + 1]) != e
        if not last:  # evenly spaced: the next camera frame, none skipped or repeated
            assert numbers[i + 1] == numbers[i] + 1
        worst_psnr = min(worst_psnr, psnr(images[i], source_rgb))
        arm, arm_age = src.latest(ARM, stamp)
        hand, hand_age = src.latest(HAND, stamp)
        np.testing.assert_array_equal(rows["observation.state"][i], np.concatenate([arm, hand]).astype(np.float32))
        grid = first_stamp[e] + int(rows["frame_index"][i]) * 1_000_000_000 // FPS
        cmd_arm, arm_wait = src.trajectory("/command/arm", grid)
        cmd_hand, hand_wait = src.trajectory("/command/hand", grid)
        np.testing.assert_allclose(rows["action"][i], np.concatenate([cmd_arm, cmd_hand]).astype(np.float32),
                                   rtol=0, atol=2e-7)
        worst_err = max(worst_err, arm_age, hand_age, arm_wait, hand_wait)
    # and LeRobotDataset's own items at chosen frames: the same values, task and picture
    for i in sorted({0, len(ds) // 3, len(ds) // 2, len(ds) - 1, int(ds.meta.episodes[1]["dataset_from_index"])}):
        item = ds[i]
        assert item["task"] == src.episodes[int(item["episode_index"])].task
        np.testing.assert_array_equal(item["observation.state"].numpy(), rows["observation.state"][i])
        np.testing.assert_array_equal(item["action"].numpy(), rows["action"][i])
        rgb = (item[CAM].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
        assert read_frame_code(rgb) == numbers[i] and psnr(rgb, images[i]) > 45
    assert worst_psnr >= 30.0
    assert worst_err <= 1e9 / FPS / 2  # 100 Hz arm, 90 Hz hand, 120 Hz commands: within half a frame
    assert report.align_err_ms == pytest.approx(worst_err / 1e6, abs=1e-6)


def test_the_sent_commands_recipe_keeps_the_first_command_sent_in_each_frame(sessions, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = tmp_path / "lab" / "sent"
    export(ExportOptions([sessions.a], "lab/sent", root, load_recipe("sent_commands")))
    ds = LeRobotDataset("lab/sent", root=root, video_backend="pyav")
    src = Source(sessions.a)
    rows = ds.hf_dataset.with_format("numpy")[:]
    from lerobot.datasets.video_utils import decode_video_frames

    checked = 0
    for e, ep in enumerate(ds.meta.episodes):
        lo, n = int(ep["dataset_from_index"]), int(ep["length"])
        t0 = float(ep[f"videos/{CAM}/from_timestamp"])
        frames = decode_video_frames(root / ds.meta.get_video_file_path(e, CAM), [t0 + k / FPS for k in range(n)], 1e-4,
                                     backend="pyav", return_uint8=True)
        numbers = [read_frame_code(img) for img in frames.permute(0, 2, 3, 1).numpy()]
        for k in range(n - 1):
            stamp, t_next = src.frames[numbers[k]][0], src.frames[numbers[k + 1]][0]
            cmd = np.concatenate([src.command("/command/arm", stamp, t_next)[0],
                                  src.command("/command/hand", stamp, t_next)[0]])
            np.testing.assert_array_equal(rows["action"][lo + k], cmd.astype(np.float32))
            checked += 1
    assert checked > 60


@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded, use of fork:DeprecationWarning")
def test_a_dataloader_with_delta_timestamps_iterates(exported_a):
    import torch

    root, _ = exported_a
    horizon = 8
    ds = load("lab/a", root, delta_timestamps={
        CAM: [-1 / FPS, 0.0], "observation.state": [-1 / FPS, 0.0], "action": [k / FPS for k in range(horizon)]})
    loader = torch.utils.data.DataLoader(ds, batch_size=16, shuffle=True, num_workers=2)  # as training runs it
    seen = 0
    last_frames = {int(ep["dataset_to_index"]) - 1 for ep in ds.meta.episodes}
    for batch in loader:
        assert batch["action"].shape[1:] == (horizon, 22)
        assert batch[CAM].shape[1:] == (2, 3, 240, 320)
        assert batch["observation.state"].shape[1:] == (2, 22)
        for j, index in enumerate(batch["index"].tolist()):
            if index in last_frames:  # the last frame of an episode: the action chunk is padding after it
                assert batch["action_is_pad"][j].tolist() == [False] + [True] * (horizon - 1)
        seen += len(batch["index"])
    assert seen == len(ds)


@pytest.fixture(scope="module")
def appended(sessions, tmp_path_factory):
    root = tmp_path_factory.mktemp("out") / "lab" / "abc"
    first = export(ExportOptions([sessions.a, sessions.b], "lab/abc", root, load_recipe()))
    second = export(ExportOptions([sessions.c], "lab/abc", root, load_recipe(), append=True))
    return root, first, second


def test_two_sessions_then_a_third_appended_give_every_episode(appended):
    root, first, second = appended
    # a: 2 episodes; b: 3 recorded, one discarded; c: 2 recorded, the first split at its camera gap
    assert (first.episodes, first.total_episodes) == (4, 4)
    b = first.sessions[1]
    assert [e.dropped for e in b.episodes] == ["", "discarded by the operator", ""]
    c = second.sessions[0]
    assert c.episodes[0].pieces == 2
    assert re.fullmatch(r"cam_front silent from 0\.[78]\d s to 1\.2\d s", c.episodes[0].gaps[0])
    assert c.episodes[1].pieces == 1 and c.episodes[1].trimmed_s == pytest.approx(0.5, abs=0.05)
    assert re.match(r"trimmed 0\.\d\d s at the start: arm_command silent from the start to 0\.50 s, effector_command",
                    c.episodes[1].notes[0])
    assert (second.episodes, second.total_episodes) == (3, 7)
    assert leftovers(root) == []
    ds = load("lab/abc", root)
    assert ds.num_episodes == 7
    assert [t for ep in ds.meta.episodes for t in ep["tasks"]] == [
        "pick_place", "pour", "hang", "cup_stack", "pour", "pour", "box_rotation"]
    assert ds.num_frames == first.frames + second.frames
    assert float(ds[len(ds) - 1]["timestamp"]) == pytest.approx(
        (int(ds.meta.episodes[6]["length"]) - 1) / FPS, abs=1e-6
    )


def test_discarded_episodes_on_request_and_gaps_that_drop_or_fail(sessions, tmp_path):
    from dataclasses import replace

    with_discarded = export(ExportOptions([sessions.b], "lab/b", tmp_path / "b", load_recipe(), include_discarded=True))
    assert with_discarded.episodes == 3 and load("lab/b", tmp_path / "b").num_episodes == 3
    recipe = load_recipe()
    drop = replace(recipe, export=replace(recipe.export, on_gap="drop"))
    report = export(ExportOptions([sessions.c], "lab/c", tmp_path / "c", drop))
    assert report.episodes == 1 and report.sessions[0].episodes[0].dropped.startswith("gap: cam_front silent from 0.")
    fail = replace(recipe, export=replace(recipe.export, on_gap="fail"))
    with pytest.raises(SessionError, match=r"c.mcap: episode 0: cam_front silent from 0\.\d\d s to 1\.\d\d s \(on_gap"):
        export(ExportOptions([sessions.c], "lab/c", tmp_path / "c2", fail))
    assert not (tmp_path / "c2").exists() and leftovers(tmp_path / "c2") == []


@pytest.mark.usefixtures("forkserver")  # workers fork with lerobot imported
def test_workers_export_the_same_dataset_merged_with_lerobots_aggregation(sessions, appended, tmp_path):
    root, _, _ = appended
    par = tmp_path / "par"
    report = export(ExportOptions([sessions.a, sessions.b, sessions.c], "lab/abc", par, load_recipe(), workers=2))
    assert report.total_episodes == 7 and leftovers(par) == []
    seq, merged = load("lab/abc", root), load("lab/abc", par)
    assert [int(n) for n in merged.meta.episodes["length"]] == [int(n) for n in seq.meta.episodes["length"]]
    for key in ("observation.state", "action", "timestamp", "episode_index", "task_index"):
        np.testing.assert_array_equal(np.asarray(merged.hf_dataset[key]), np.asarray(seq.hf_dataset[key]))
    a, b = merged[len(merged) - 1][CAM], seq[len(seq) - 1][CAM]
    assert a.shape == b.shape and float((a - b).abs().max()) < 1e-6  # same encoder, same frames
    assert merged.meta.info.features[CAM]["info"]["video.codec"] == "h264"
    # appending with workers: the existing dataset and the new parts, aggregated into a new one
    more = export(ExportOptions([sessions.b, sessions.c], "lab/abc", par, load_recipe(), workers=2, append=True))
    assert (more.episodes, more.total_episodes) == (5, 12) and leftovers(par) == []
    grown = load("lab/abc", par)
    assert grown.num_episodes == 12
    n = merged.num_frames
    np.testing.assert_array_equal(np.asarray(grown.hf_dataset["action"][:n]), np.asarray(merged.hf_dataset["action"]))
    # Ctrl-C while the workers run: they are stopped and their parts removed with the staging folder
    stopped = tmp_path / "stopped"

    def ctrl_c(progress):
        if progress.kind == "frames":
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        export(ExportOptions([sessions.a, sessions.b, sessions.c], "lab/s", stopped, load_recipe(), workers=2), ctrl_c)
    assert not stopped.exists() and leftovers(stopped) == []


def test_two_cameras_and_the_glove_recipe(tmp_path):
    """Every camera becomes a video; the second camera shows its latest frame at or before the
    reference camera's; the glove recipe adds the raw glove, the wrist pose and the pipeline's joints."""
    from teleprev.export.synthetic import GLOVE_JOINTS

    path = write_session(tmp_path / "two.mcap", SyntheticSession(
        (EpisodeSpec("pour", 1.5),), cameras=("cam_front", "cam_wrist"), width=128, height=96, seed=5))
    root = tmp_path / "out" / "two"
    report = export(ExportOptions([path], "lab/two", root, load_recipe("with_glove")))
    ds = load("lab/two", root)
    f = ds.features
    assert f["observation.images.cam_front"]["dtype"] == f["observation.images.cam_wrist"]["dtype"] == "video"
    assert f["observation.glove"]["names"] == [f"glove.{j}" for j in GLOVE_JOINTS] and len(GLOVE_JOINTS) == 45
    assert f["observation.wrist"]["names"] == [
        "wrist.x",
        "wrist.y",
        "wrist.z",
        "wrist.qx",
        "wrist.qy",
        "wrist.qz",
        "wrist.qw",
    ]
    assert f["corrected"]["names"] == [f"corrected.{i}" for i in range(16)]
    assert f["retargeted"]["names"] == [f"retargeted.{i}" for i in range(16)]
    with SessionReader(path) as r:
        frames = {}
        for m in r.messages(["/camera/cam_front/image", "/camera/cam_wrist/image"]):
            rgb = cv2.imdecode(np.frombuffer(m.payload.data, np.uint8), cv2.IMREAD_COLOR_RGB)
            frames[(m.topic.split("/")[2], read_frame_code(rgb))] = m.payload.stamp_ns
        wrist_samples = [
            (m.payload.stamp_ns, np.r_[m.payload.position, m.payload.orientation])
            for m in r.messages(["/suit/suit/wrist"])
        ]
    wrist_stamps = np.array([t for t, _ in wrist_samples])
    for i in (0, len(ds) // 2, len(ds) - 1):
        item = ds[i]
        codes = {
            cam: read_frame_code(
                (item[f"observation.images.{cam}"].permute(1, 2, 0).numpy() * 255).round().astype(np.uint8)
            )
            for cam in ("cam_front", "cam_wrist")
        }
        t = frames[("cam_front", codes["cam_front"])]
        t_wrist = frames[("cam_wrist", codes["cam_wrist"])]
        later = [s for (cam, _), s in frames.items() if cam == "cam_wrist" and t_wrist < s <= t]
        assert t_wrist <= t and not later  # the latest wrist-camera frame at or before the frame's time
        j = np.searchsorted(wrist_stamps, t, side="right") - 1
        np.testing.assert_array_equal(item["observation.wrist"].numpy(), wrist_samples[j][1].astype(np.float32))
    assert report.sessions[0].image_err_ms <= 1000 / FPS  # the second camera's frame is at most a period old


def test_a_session_without_camera_runs_on_a_fixed_clock(tmp_path):
    path = write_session(tmp_path / "blind.mcap", SyntheticSession((EpisodeSpec("pour", 2.0),), cameras=(), seed=6))
    root = tmp_path / "out" / "blind"
    report = export(ExportOptions([path], "lab/blind", root, load_recipe()))
    ds = load("lab/blind", root)
    assert ds.fps == 30 and not ds.meta.video_keys
    assert ds.num_frames == report.frames and abs(ds.num_frames - 60) <= 1
    assert report.align_err_ms <= 1000 / FPS / 2


def test_a_target_that_exists_is_refused_and_left_alone(sessions, exported_a):
    root, _ = exported_a
    before = sorted(str(p.relative_to(root)) for p in root.rglob("*"))
    with pytest.raises(ConfigError, match="already exists; pass --append"):
        export(ExportOptions([sessions.b], "lab/a", root, load_recipe()))
    assert sorted(str(p.relative_to(root)) for p in root.rglob("*")) == before
    with pytest.raises(ConfigError, match="--append: there is no dataset here"):
        export(ExportOptions([sessions.b], "lab/x", root.parent / "nothing", load_recipe(), append=True))
    assert not (root.parent / "nothing").exists()


def test_a_truncated_session_fails_before_anything_is_written(sessions, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = sessions.b.read_bytes()
    cut.write_bytes(data[: len(data) * 6 // 10])
    root = tmp_path / "out" / "ds"
    with pytest.raises(SessionError, match=r"cut.mcap: the file is cut short.*teleprev recover"):
        export(ExportOptions([sessions.a, cut], "lab/cut", root, load_recipe()))
    assert not root.exists() and leftovers(root) == []


def test_a_session_without_the_requested_streams_is_named(tmp_path):
    preview = write_session(tmp_path / "preview.mcap", SyntheticSession(
        (EpisodeSpec("pour", 1.0, commands_after_s=5.0),), width=64, height=48, extra_topics=False))
    root = tmp_path / "out" / "ds"
    with pytest.raises(SessionError, match=r"preview.mcap: feature 'action': stream 'arm_command' \(/command/arm\) "
                                           r"is not in this session"):
        export(ExportOptions([preview], "lab/p", root, load_recipe()))
    plain = write_session(tmp_path / "plain.mcap", SyntheticSession(
        (EpisodeSpec("pour", 1.0),), width=64, height=48, extra_topics=False))
    with pytest.raises(SessionError, match="plain.mcap: feature 'observation.glove': stream 'glove': this session has "
                                           "no glove device"):
        export(ExportOptions([plain], "lab/p", root, load_recipe("with_glove")))
    assert not root.exists() and leftovers(root) == []


def corrupt_copy(src: Path, dst: Path, episode: int) -> Path:
    """The session rewritten message by message, with one camera frame of `episode` replaced by junk."""
    with SessionReader(src) as r:
        start = r.episodes()[episode].start_ns
        meta = {k: v for k, v in r.metadata.items() if k != "teleprev"}
        done = False
        with McapSessionWriter(dst, meta, fsync=False) as w:
            for m in r.messages():
                p = m.payload
                if isinstance(p, ImageSample) and not done and p.stamp_ns > start + 500_000_000:
                    p, done = ImageSample(p.stamp_ns, p.frame_id, b"\xff\xd8 not a jpeg", "jpeg"), True
                w.write(Logged(m.topic, m.log_time_ns, p))
    return dst


def test_a_failure_half_way_leaves_no_half_dataset_and_no_changed_one(sessions, exported_a, tmp_path):
    bad = corrupt_copy(sessions.a, tmp_path / "bad.mcap", episode=1)
    root = tmp_path / "out" / "ds"
    with pytest.raises(
        SessionError, match=r"bad.mcap: the image on /camera/cam_front/image at log time \d+ does not decode"
    ):
        export(ExportOptions([sessions.b, bad], "lab/bad", root, load_recipe()))
    assert not root.exists() and leftovers(root) == []
    # appending the same session to a dataset fails the same way, and the dataset stays as it was
    existing, _ = exported_a
    files = {p: p.read_bytes() for p in existing.rglob("*") if p.is_file()}
    with pytest.raises(SessionError, match="does not decode"):
        export(ExportOptions([bad], "lab/a", existing, load_recipe(), append=True))
    assert {p: p.read_bytes() for p in existing.rglob("*") if p.is_file()} == files
    assert leftovers(existing) == []
    assert load("lab/a", existing).num_episodes == 2


def test_an_interrupted_export_leaves_nothing(sessions, tmp_path):
    root = tmp_path / "out" / "ds"

    def ctrl_c(progress):
        if progress.kind == "frames":  # half way through the first episode, encoder running
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        export(ExportOptions([sessions.a], "lab/i", root, load_recipe()), ctrl_c)
    assert not root.exists() and leftovers(root) == []


def test_skipping_lerobots_noop_image_embedding_gives_the_same_table():
    import datasets
    from teleprev.export.dataset import prepare_lerobot

    prepare_lerobot()
    from lerobot.datasets import dataset_writer

    ours = dataset_writer.embed_images
    theirs = ours.lerobot_embed_images
    video_only = datasets.Dataset.from_dict(
        {"observation.state": np.arange(12, dtype=np.float32).reshape(4, 3), "index": np.arange(4)},
        features=datasets.Features({"observation.state": datasets.List(datasets.Value("float32"), length=3),
                                    "index": datasets.Value("int64")}))
    assert ours(video_only) is video_only
    assert theirs(video_only).with_format("arrow")[:].equals(video_only.with_format("arrow")[:])
    png = cv2.imencode(".png", np.zeros((4, 4, 3), np.uint8))[1].tobytes()
    with_images = datasets.Dataset.from_dict({"image": [{"bytes": png, "path": None}]},
                                             features=datasets.Features({"image": datasets.Image()}))
    assert ours(with_images) is not with_images  # image columns still go through lerobot's embedding


def test_the_command_line_exports_and_refuses_clearly(sessions, tmp_path):
    import json

    from typer.testing import CliRunner

    from teleprev.cli.app import app

    root = tmp_path / "cli"
    result = CliRunner().invoke(app, ["export", str(sessions.a), "--repo-id", "lab/cli", "--root", str(root), "--json",
                                      "--crf", "28", "--fps", "15"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["episodes"] == 2 and out["fps"] == 15 and out["max_align_err_ms"] <= 1000 / 15 / 2
    assert out["frames"] == load("lab/cli", root).num_frames
    again = CliRunner().invoke(app, ["export", str(sessions.a), "--repo-id", "lab/cli", "--root", str(root)])
    assert again.exit_code != 0 and "already exists" in str(again.exception)
    shutil.rmtree(root)
