"""`teleprev replay --out SESSION.mcap`: a replay recorded as a session of its own: every command sent to
the robot (the engage ramp and the played steps) on /command/arm and /command/hand as it leaves, the
states the robot reports, one episode around the played steps, and the rig in the metadata, so that
`teleprev audit`, `replay` and `export` read it like any recording.
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

from teleprev import __version__, topics
from teleprev.errors import ConfigError, SessionError, describe_os_error
from teleprev.messages import Event, JointSample, Logged

_COMMAND_TOPICS = {"arm": topics.COMMAND_ARM, "hand": topics.COMMAND_HAND}
TASK = "replay"
FLUSH_S = 1.0  # a crash loses at most about this much of the recording
_END = object()


def check_out(out: Path) -> None:
    """Refuse an --out that would overwrite something or cannot be created, before anything opens."""
    out = Path(out)
    if out.exists():
        raise ConfigError("already exists; teleprev does not overwrite a recording", str(out))
    if not out.parent.is_dir():
        raise ConfigError("the folder to write the replay's session in does not exist", str(out.parent))


class ReplayRecording:
    """Messages are queued by the threads that send and receive them and written by a thread of the
    recording's own, flushed at least once a second: a slow disk never delays a command."""

    def __init__(self, out: Path, rig, source: Path, episode: int | None, clock):
        from teleprev.live.session import rig_record
        from teleprev.session.writer import McapSessionWriter

        self.clock = clock
        meta = {"rig": rig_record(rig),
                "session": {"task": TASK, "operator": "", "end_effector": rig.rig.end_effector, "software_version": __version__},
                "replay": {"source": str(source), "episode": "" if episode is None else str(episode)}}
        self.writer = McapSessionWriter(out, meta)
        self.started = False
        self.error = ""  # why the recording stopped early ("" while it has not)
        self.playing = lambda: True  # whether the player is past its engage ramp (build_player sets it)
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._drain, name="replay-recording", daemon=True)
        self._thread.start()

    def _write(self, topic: str, log_ns: int, payload) -> None:
        self._queue.put(Logged(topic, log_ns, payload))

    def _drain(self) -> None:
        flushed = time.monotonic()
        while True:
            try:
                msg = self._queue.get(timeout=FLUSH_S)
            except queue.Empty:
                msg = None
            if msg is _END:
                return
            if self.error:
                continue  # stopped: the queue is still emptied
            try:
                if msg is not None:
                    self.writer.write(msg)
                if time.monotonic() - flushed >= FLUSH_S:
                    self.writer.flush()
                    flushed = time.monotonic()
            except OSError as exc:  # a full disk stops the recording, never the commands to the robot
                self.error = describe_os_error(exc)
                self.writer.abort()

    def _episode(self, event: str) -> None:
        now = self.clock.now_ns()
        self._write(topics.EPISODE, now, Event(now, "teleprev.EpisodeEvent", {"event": event, "episode": 0, "task": TASK}))

    def actuators(self, devices: dict) -> dict:
        """The devices, each wrapped so that every command it is sent is recorded first."""
        return {kind: _Recorded(device, _COMMAND_TOPICS[kind], self) for kind, device in devices.items()}

    def sink(self, then):
        """A runner's sink that records the robot's states, then hands them to `then`."""
        def record(sample, receive_ns: int) -> None:
            if isinstance(sample.payload, JointSample):
                self._write(sample.topic, receive_ns, sample.payload)
            then(sample, receive_ns)
        return record

    def command(self, topic: str, sample: JointSample) -> None:
        if not self.started and self.playing():  # the episode is what is played; the engage ramp comes before it
            self.started = True
            self._episode("start")
        self._write(topic, self.clock.now_ns(), sample)

    def close(self) -> None:
        """Write what is queued and close the file (`error` says if the recording had to stop early)."""
        if self.started:
            self._episode("stop")
        self._queue.put(_END)
        self._thread.join()
        if self.error:
            return
        try:
            self.writer.close()
        except OSError as exc:
            self.error = describe_os_error(exc)
            self.writer.abort()

    def check(self) -> None:
        """Raise SessionError if the recording had to stop early."""
        if self.error:
            raise SessionError(f"the replay's recording stopped early: {self.error} (what was flushed before is kept)",
                               str(self.writer.path))


class _Recorded:
    """An actuator whose commands a ReplayRecording records as they are sent."""

    def __init__(self, device, topic: str, recording: ReplayRecording):
        self.device, self.topic, self.recording = device, topic, recording

    def send(self, sample: JointSample):
        self.recording.command(self.topic, sample)
        return self.device.send(sample)

    def __getattr__(self, name):
        return getattr(self.device, name)
