"""`teleprev replay --out SESSION.mcap`: a replay recorded as a session of its own: every command sent to
the robot (the engage ramp and the played steps) on /command/arm and /command/hand as it leaves (and, for an
actuator in a process of its own, each write on /command/wire), the states the robot reports, the source
session's camera frames (colour, depth, calibration) as their instants are played
(teleprev/live/replay/camera_carry.py), one episode around the played steps, and the rig in the metadata, so
that `teleprev audit`, `replay` and `export` read it like any recording.
"""

from __future__ import annotations

from pathlib import Path

from teleprev import __version__, topics
from teleprev.errors import SessionError, describe_os_error
from teleprev.messages import Event, JointSample, Logged

_COMMAND_TOPICS = {"arm": topics.COMMAND_ARM, "hand": topics.COMMAND_HAND}
TASK = "replay"


class ReplayRecording:
    """The session's own Recorder (teleprev/session/recorder.py) writes it: messages are queued by the
    threads that send and receive them and written by the recorder's thread, flushed twice a second, so a
    slow or full disk never delays or stops a command."""

    def __init__(self, out: Path, rig, source: Path, episode: int | None, clock):
        from teleprev.live.record.metadata import rig_record
        from teleprev.session.recorder import Recorder

        self.clock = clock
        meta = {
            "rig": rig_record(rig),
            "session": {
                "task": TASK,
                "operator": "",
                "end_effector": rig.rig.end_effector,
                "software_version": __version__,
            },
            "replay": {"source": str(source), "episode": "" if episode is None else str(episode)},
        }
        self.recorder = Recorder(out, meta).start()
        self.started = False
        self.playing = lambda: True  # whether the player is past its engage ramp (build_player sets it)
        self.carry = None  # the source session's camera frames (a CameraCarry, which build_player sets), or None

    @property
    def error(self) -> str:
        """Why the recording stopped early ("" while it has not)."""
        failure = self.recorder.failure
        return describe_os_error(failure) if failure is not None else ""

    def _write(self, topic: str, log_ns: int, payload) -> None:
        self.recorder.log(Logged(topic, log_ns, payload))  # refused quietly once the recording has failed

    def _episode(self, event: str) -> None:
        now = self.clock.now_ns()
        self._write(
            topics.EPISODE, now, Event(now, "teleprev.EpisodeEvent", {"event": event, "episode": 0, "task": TASK})
        )

    def actuators(self, devices: dict, side: str = "") -> dict:
        """The devices, each wrapped so that every command it is sent is recorded first; `side`: a bimanual
        rig's side, whose commands go on /command/<side>/arm and /command/<side>/hand."""
        from teleprev.pipeline.bimanual import side_topic

        return {kind: _Recorded(device, side_topic(_COMMAND_TOPICS[kind], side) if side else _COMMAND_TOPICS[kind],
                                self) for kind, device in devices.items()}

    def sink(self, then):
        """A runner's sink that records the robot's states, then hands them to `then`."""
        def record(sample, receive_ns: int) -> None:
            if isinstance(sample.payload, JointSample):
                self._write(sample.topic, receive_ns, sample.payload)
            then(sample, receive_ns)
        return record

    def record(self, topic: str, payload) -> None:
        """A message recorded as it arrives (the source's camera frames: teleprev/live/replay/camera_carry.py)."""
        self._write(topic, self.clock.now_ns(), payload)

    def command(self, topic: str, sample: JointSample) -> None:
        if not self.started and self.playing():  # the episode is what is played; the engage ramp comes before it
            self.started = True
            self._episode("start")
        self._write(topic, self.clock.now_ns(), sample)

    def wired(self, record) -> None:
        """A command as its actuator's process wrote it (actuator_host.WireRecord): /command/wire, stamped
        when the write began, as a recording has it."""
        self._write(topics.COMMAND_WIRE, self.clock.now_ns(),
                    Event(record.wire_ns, "teleprev.CommandWire", record.event_data()))

    def close(self) -> None:
        """Write what is queued and close the file (`error` says if the recording had to stop early)."""
        if self.started:
            self._episode("stop")
        try:
            self.recorder.close()
        except SessionError:
            pass  # the failure is kept by the recorder: `error` and `check` say it

    def check(self) -> None:
        """Raise SessionError if the recording had to stop early."""
        if self.error:
            raise SessionError(f"the replay's recording stopped early: {self.error} (what was flushed before is kept)",
                               str(self.recorder.path))


class _Recorded:
    """An actuator whose commands a ReplayRecording records as they are sent."""

    def __init__(self, device, topic: str, recording: ReplayRecording):
        self.device, self.topic, self.recording = device, topic, recording

    def send(self, sample: JointSample):
        self.recording.command(self.topic, sample)
        return self.device.send(sample)

    def __getattr__(self, name):
        return getattr(self.device, name)
