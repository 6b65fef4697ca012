"""`teleprev replay SESSION --out` keeps the session's cameras: a physics-rig session whose camera recorded depth,
replayed to the sim, records every depth frame (and colour and calibration) of the played window, unchanged,
at the instant the replay played it; the replay session exports to a dataset with the depth feature. A dataset
with depth, replayed --out, records its depth maps too (as lerobot reads them back, in 1 mm counts). `teleprev
eval` writes no session (a report and plots of the re-run pipeline, which takes no camera): a session with depth
evaluates as any other, reproduced bit for bit, its depth never read."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from teleprev import topics
from teleprev.messages import CameraInfo, DepthSample
from teleprev.session.reader import SessionReader
from tests.helpers.cli import teleprev
from tests.helpers.depth_session import depth_physics_rig

W, H = 160, 120
CAMERA = "/camera/cam_front"


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    d = tmp_path_factory.mktemp("depth_replay")
    ran = teleprev("record", depth_physics_rig(d, W, H), "--out", d / "demo.mcap", "--episodes", "1",
                   "--episode-time", "3.0", "--engage-after", "0.3", "--no-preview")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    return d / "demo.mcap"


@pytest.fixture(scope="module")
def dataset(source):
    root = source.parent / "ds"
    ran = teleprev("export", source, "--repo-id", "lab/depth_demo", "--root", root)
    assert ran.returncode == 0, ran.stderr + ran.stdout
    return root


def _read(path):
    with SessionReader(path) as reader:
        got = {t: [m.payload for m in reader.messages([t])] if t in reader.topics else []
               for t in (f"{CAMERA}/depth", f"{CAMERA}/calibration", f"{CAMERA}/image", topics.COMMAND_ARM)}
        return got, reader.episodes()


@pytest.mark.parametrize("speed", [1.0, 0.5])
def test_a_replay_records_the_sessions_depth_as_it_plays_it(source, tmp_path, speed):
    out = tmp_path / "replay.mcap"
    ran = teleprev("replay", source, "--episode", "0", "--to", "sim", "--engage-after", "0.2", "--no-preview",
                   "--speed", speed, "--out", out)
    assert ran.returncode == 0, ran.stderr + ran.stdout
    speed = float(re.search(r"played \d+ steps at ([0-9.]+)x", ran.stdout).group(1))  # (capped by the limits)
    src, _ = _read(source)
    got, episodes = _read(out)
    commands = [c.stamp_ns for c in src[topics.COMMAND_ARM]]
    t0, last = min(commands), max(commands)
    played = [d for d in src[f"{CAMERA}/depth"] if t0 <= d.stamp_ns <= last]
    depths = got[f"{CAMERA}/depth"]
    assert len(played) >= 20 and [d.stamp_ns for d in depths] == sorted(d.stamp_ns for d in depths)
    assert len(depths) == len(played)  # every frame of the played window, once
    for a, b in zip(played, depths):
        assert isinstance(b, DepthSample) and np.array_equal(a.depth, b.depth) and b.scale_m == a.scale_m
    # stamped at the instant the replay played it: the source's intervals over the speed
    src_dt = np.diff([d.stamp_ns for d in played]) / speed
    assert np.abs(np.diff([d.stamp_ns for d in depths]) - src_dt).max() <= 1
    (episode,) = episodes
    assert episode.start_ns - 50_000_000 <= depths[0].stamp_ns and depths[-1].stamp_ns <= episode.stop_ns
    infos = got[f"{CAMERA}/calibration"]
    assert infos and all(isinstance(i, CameraInfo) and (i.width, i.height) == (W, H) for i in infos)
    assert infos[0].k == src[f"{CAMERA}/calibration"][0].k
    assert len(got[f"{CAMERA}/image"]) == len([i for i in src[f"{CAMERA}/image"] if t0 <= i.stamp_ns <= last])


def _worlds() -> set[int]:
    """The physics world processes this process started that are running."""
    import psutil

    return {c.pid for c in psutil.Process().children() if "teleprev.world.process" in " ".join(c.cmdline())}


def test_the_replay_session_exports_with_its_depth(source, tmp_path):
    out = tmp_path / "replay.mcap"
    before = _worlds()
    ran = teleprev("replay", source, "--episode", "0", "--to", "sim", "--engage-after", "0.2", "--no-preview",
                   "--out", out)
    assert ran.returncode == 0, ran.stderr + ran.stdout
    assert _worlds() <= before  # the replay closed the world its sim devices stepped (run here, not in a child)
    ran = teleprev("export", out, "--repo-id", "lab/replayed", "--root", tmp_path / "ds")
    assert ran.returncode == 0, ran.stderr + ran.stdout
    info = json.loads((tmp_path / "ds" / "meta" / "info.json").read_text())
    feature = info["features"]["observation.images.cam_front_depth"]
    assert feature["shape"] == [H, W, 1] and feature["info"]["is_depth_map"] is True
    assert info["total_frames"] >= 10  # (about 70 on a quiet machine: the engaged 2.4 s of the episode)


def test_a_datasets_depth_is_recorded_when_its_actions_are_replayed(source, dataset, tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    out = tmp_path / "replay.mcap"
    ran = teleprev("replay", dataset, "--config", source.parent / "sim_physics_depth.toml", "--episode", "0",
                   "--to", "sim", "--smooth", "--engage-after", "0.2", "--no-preview", "--out", out)
    assert ran.returncode == 0, ran.stderr + ran.stdout
    got, (episode,) = _read(out)
    depths = got[f"{CAMERA}/depth"]
    ds = LeRobotDataset("lab/depth_demo", root=dataset, video_backend="pyav", depth_output_unit="m")
    assert len(depths) == len(ds) >= 20  # every frame of the episode (its first action's frame on)
    assert not got[f"{CAMERA}/calibration"]  # a dataset keeps no intrinsics
    frame_dt = np.diff([round(float(ds[k]["timestamp"]) * 1e9) for k in range(len(ds))])
    assert np.abs(np.diff([d.stamp_ns for d in depths]) - frame_dt).max() <= 1
    for k in (0, len(ds) // 2, len(ds) - 1):
        want = ds[k]["observation.images.cam_front_depth"].numpy().reshape(H, W)
        d = depths[k]
        assert d.scale_m == 0.001 and d.depth.shape == (H, W)
        seen = want > 0.0101  # lerobot reads "no return" back as its depth_min, 0.01 m: it is no return again
        assert np.abs(d.metres()[seen] - want[seen]).max() <= 0.0005 + 1e-6  # 1 mm counts: half a count at most
        assert not d.depth[~seen].any()
        assert seen.mean() > 0.2 and np.median(d.metres()[seen]) > 0.3  # (the front view sees the room past 10 m)


def test_eval_of_a_session_with_depth_reproduces_it_without_reading_the_depth(source, tmp_path, monkeypatch):
    from teleprev.session import reader as session_reader

    decoded = []
    real = session_reader.SessionReader.messages

    def counting(self, topics=None, *args, **kwargs):
        decoded.extend(topics or ["(every topic)"])
        return real(self, topics, *args, **kwargs)

    monkeypatch.setattr(session_reader.SessionReader, "messages", counting)
    ran = teleprev("eval", source, "--out", tmp_path / "eval.json")
    assert ran.returncode == 0 and "bit for bit" in ran.stdout, ran.stdout + ran.stderr
    assert decoded and not [t for t in decoded if t.startswith("/camera/") or t == "(every topic)"], decoded
    report = json.loads((tmp_path / "eval.json").read_text())
    assert report["sessions"][0]["bit_identical"] is True
