"""The source session's camera streams carried into a replay's recording (`replay SESSION --out`): colour,
depth and calibration, each frame recorded as the player plays the instant it was taken, so that the replay
session holds what the cameras saw beside the commands it sent (and `export` makes data of it, depth included).

A frame taken at `t` on the source's clock is stamped `start + (t - t0) / speed` on the replay's (`t0` the first
played step, `start` when the player sent it) and logged when the replay's clock reaches that instant, in order
with the commands. It is read and written on a thread of its own: a slow disk or a large depth frame never delays
a command. Frames before the first played step or after the last are left out; a replay stopped early carries
the frames up to where it stopped.
"""

from __future__ import annotations

import threading
from dataclasses import replace
from pathlib import Path

from teleprev.session.reader import SessionReader
from teleprev.topics import parse_device_topic


def camera_topics(reader: SessionReader) -> list[str]:
    """The camera streams a session recorded (/camera/<device>/<stream>), in topic order."""
    return sorted(t for t in reader.schemas if (parsed := parse_device_topic(t)) and parsed[0] == "camera")


class CameraCarry:
    """Carries `session`'s camera frames into `recording` (a ReplayRecording) as `player` plays them."""

    POLL_S = 0.05  # how often the thread looks whether the player has started

    def __init__(self, session: Path, recording, player):
        self.session, self.recording, self.player = session, recording, player
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
        with SessionReader(self.session) as reader:
            wanted = camera_topics(reader)
            if not wanted:
                return
            # log times follow acquisition stamps within a camera's latency: a second's margin either side
            for msg in reader.messages(wanted, start_ns=t0 - 1_000_000_000, end_ns=last + 1_000_000_000):
                stamp = msg.payload.stamp_ns
                if stamp < t0:
                    continue
                if stamp > last:
                    break
                due = start_ns + int(round((stamp - t0) / speed))
                while True:
                    if self._stop.is_set():
                        if due > self._played_until(start_ns, t0, speed):
                            return
                        break  # an instant the player played before it stopped: written at once
                    wait_s = (due - clock.now_ns()) / 1e9
                    if wait_s <= 0:
                        break
                    self._stop.wait(min(wait_s, self.POLL_S))
                self.recording.record(msg.topic, replace(msg.payload, stamp_ns=due))
                self.carried[msg.topic] = self.carried.get(msg.topic, 0) + 1

    def _played_until(self, start_ns: int, t0: int, speed: float) -> int:
        """The replay's instant of the last step the player played."""
        return start_ns + int(round((int(self.player.p.t_ns[self.player.state.index]) - t0) / speed))
