"""The source's camera streams carried into a replay's recording (`replay SOURCE --out`), each frame recorded as
the player plays the instant it was taken, so that the replay session holds what the cameras saw beside the
commands it sent (and `export` makes data of it, depth included):

    session_frames(path)              a session's colour, depth and calibration (/camera/<device>/*), as recorded
    dataset_depth_frames(root, ep)    a LeRobot dataset's depth maps (its is_depth_map features
                                      observation.images.<camera>_depth) as /camera/<camera>/depth, in counts
                                      of DATASET_DEPTH_UNIT_M (a dataset keeps no intrinsics: no calibration)

A frame taken at `t` on the source's clock is stamped `start + (t - t0) / speed` on the replay's (`t0` the first
played step, `start` when the player sent it) and logged when the replay's clock reaches that instant, in order
with the commands. It is read and written on a thread of its own: a slow disk or a large depth frame never delays
a command. Frames before the first played step or after the last are left out; a replay stopped early carries
the frames up to where it stopped.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from teleprev.messages import DepthSample
from teleprev.session.reader import SessionReader
from teleprev.topics import device_topic, parse_device_topic

# (t0, last) -> the frames (topic, payload) stamped from t0 to last on the source's clock, as they were logged
# (each topic in stamp order; across topics within their latencies)
Frames = Callable[[int, int], Iterator[tuple[str, object]]]
DATASET_DEPTH_UNIT_M = 0.001  # a dataset's depth (metres, float) as 16-bit counts: finer than its 12-bit steps
LATENCY_MARGIN_NS = 5_000_000_000  # frames logged up to this long after they were taken are carried
DEPTH_MIN_M = 0.01  # lerobot.configs.video.DEFAULT_DEPTH_MIN: a depth feature's depth_min where its info has none
DEPTH_SUFFIX = "_depth"  # LeRobot's depth feature: observation.images.<camera>_depth


def camera_topics(reader: SessionReader) -> list[str]:
    """The camera streams a session recorded (/camera/<device>/<stream>), in topic order."""
    return sorted(t for t in reader.schemas if (parsed := parse_device_topic(t)) and parsed[0] == "camera")


def session_frames(session: Path) -> Frames:
    def frames(t0: int, last: int):
        with SessionReader(session) as reader:
            wanted = camera_topics(reader)
            if not wanted:
                return
            # in log-time order, which follows each camera's stamps within its latency (a busy machine's included:
            # LATENCY_MARGIN_NS); one topic's frame past `last` may come before another's within it
            for msg in reader.messages(wanted, start_ns=t0 - 1_000_000_000, end_ns=last + LATENCY_MARGIN_NS):
                if t0 <= msg.payload.stamp_ns <= last:
                    yield msg.topic, msg.payload
    return frames


def depth_features(root: Path) -> list[str]:
    """A LeRobot dataset's depth-map features (info.json alone: no lerobot)."""
    features = json.loads((Path(root) / "meta" / "info.json").read_text()).get("features", {})
    return sorted(k for k, f in features.items() if (f.get("info") or {}).get("is_depth_map"))


def dataset_depth_frames(root: Path, episode: int) -> Frames | None:
    """The depth maps of one episode of a dataset, read back by lerobot (in metres), or None where it has none.
    lerobot is imported here, before the replay plays (its import would hold the interpreter for seconds)."""
    keys = depth_features(root)
    if not keys:
        return None
    info = json.loads((Path(root) / "meta" / "info.json").read_text())
    # lerobot's quantiser clips "no return" (0) up to its depth_min: read back, that is no return again
    nearest = {k: float(info["features"][k]["info"].get("video.depth_min", DEPTH_MIN_M)) for k in keys}
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    repo_id = info.get("repo_id") or Path(root).name

    def frames(t0: int, last: int):
        ds = LeRobotDataset(repo_id, root=root, episodes=[episode], video_backend="pyav", depth_output_unit="m")
        for k in range(len(ds)):
            item = ds[k]
            stamp = int(round(float(item["timestamp"]) * 1e9))
            if stamp < t0:
                continue
            if stamp > last:
                break
            for key in keys:
                camera = key.rsplit(".", 1)[-1].removesuffix(DEPTH_SUFFIX)
                metres = item[key].numpy().reshape(item[key].shape[-2:])
                counts = np.clip(np.rint(metres / DATASET_DEPTH_UNIT_M), 0, 65535).astype(np.uint16)
                counts[metres < nearest[key] + 1e-4] = 0  # (its steps there are 1.2 mm; float32 reads it 1e-7 off)
                yield device_topic("camera", camera, "depth"), DepthSample(stamp, camera, counts, DATASET_DEPTH_UNIT_M)
    return frames


class CameraCarry:
    """Carries a source's camera frames into `recording` (a ReplayRecording) as `player` plays them."""

    POLL_S = 0.05  # how often the thread looks whether the player has started

    def __init__(self, frames: Frames, recording, player):
        self.frames, self.recording, self.player = frames, recording, player
        self.carried: dict[str, int] = {}  # topic -> frames recorded
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="replay-cameras", daemon=True)

    def start(self) -> CameraCarry:
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """No frame more: the player is done or stopped (frames of instants it played are written first)."""
        self._stop.set()
        self._thread.join(timeout_s)

    def _run(self) -> None:
        player, clock = self.player, self.recording.clock
        while player.state.start_ns is None:
            if self._stop.wait(self.POLL_S) or player.state.mode == "done":
                return
        p, start_ns, speed = player.p, player.state.start_ns, player.speed
        t0, last = int(p.t_ns[0]), int(p.t_ns[-1])
        for topic, payload in self.frames(t0, last):
            due = start_ns + int(round((payload.stamp_ns - t0) / speed))
            while True:
                if self._stop.is_set():
                    if due > self._played_until(start_ns, t0, speed):
                        return
                    break  # an instant the player played before it stopped: written at once
                wait_s = (due - clock.now_ns()) / 1e9
                if wait_s <= 0:
                    break
                self._stop.wait(min(wait_s, self.POLL_S))
            self.recording.record(topic, replace(payload, stamp_ns=due))
            self.carried[topic] = self.carried.get(topic, 0) + 1

    def _played_until(self, start_ns: int, t0: int, speed: float) -> int:
        """The replay's instant of the last step the player played."""
        return start_ns + int(round((int(self.player.p.t_ns[self.player.state.index]) - t0) / speed))
