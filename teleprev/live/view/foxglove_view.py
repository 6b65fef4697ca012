"""A live Foxglove view of a recording or a replay: foxglove-sdk's WebSocket server on 127.0.0.1, carrying
every message the session file gets, on the same topics with the same schemas (the robot included:
/robot_description and /tf). Open it in Foxglove with "Open connection", ws://127.0.0.1:<port>.

Every topic a recording or a replay will have is declared before the server starts, so before a client
can connect: a client connected while channels appear can have its subscriptions to some of them refused
("unknown channel", seen with foxglove-sdk 0.30: a replay then showed no /tf one time in three), and a
Foxglove window opened before the camera's first frame would show no camera.

Publishing never holds up the session: `log()` queues the message (a full queue drops it and counts
it) and one thread encodes and sends. What a late joiner needs is latched: /robot_description (sent once
per session) and the last /events/mode are sent again to each client when it subscribes to them, once.
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

import numpy as np

from teleprev import topics as T
from teleprev.errors import ConfigError
from teleprev.live.view.foxglove_front import SubprotocolFront
from teleprev.messages import Event, ImageSample, JointSample, Logged, PoseSample, RobotDescription, TransformsSample
from teleprev.session.codec import encode, schema_for
from teleprev.topics import ROBOT_DESCRIPTION

DEFAULT_PORT = 8765  # Foxglove's usual WebSocket port
HOST = "127.0.0.1"  # loopback only: reach it from another machine through an SSH tunnel
_STOP = object()


LATCHED = (ROBOT_DESCRIPTION, T.MODE)  # topics whose last message a client gets when it subscribes


class FoxgloveView:
    def __init__(self, port: int = DEFAULT_PORT, channels: dict[str, object] | None = None, queue_size: int = 4096):
        """A server on 127.0.0.1:`port` (0: any free port) with `channels` (topic -> a payload of its type,
        see session_channels and file_channels) declared before it starts."""
        import foxglove
        from foxglove.websocket import ServerListener

        view = self

        class _Listener(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                latched = view._latched.get(channel.topic)
                if latched is not None:
                    view._queue.put(latched)

        if not 0 <= port <= 65535:
            raise ConfigError(f"--foxglove: {port} is not a TCP port (0..65535)")
        self._context = foxglove.Context()
        self._channels: dict[str, object] = {}
        self._latched: dict[str, Logged] = {}
        for topic, payload in (channels or {}).items():
            self.declare(topic, payload)
        try:  # foxglove-sdk's server on a private port, behind the front that accepts both protocol names
            self._server = foxglove.start_server(name="teleprev", host=HOST, port=0, context=self._context,
                                                 server_listener=_Listener())
        except Exception as exc:  # foxglove raises its own error types for a port in use or refused
            raise ConfigError(f"cannot start the Foxglove server on {HOST} ({exc})") from None
        try:
            self._front = SubprotocolFront(HOST, port, self._server.port)
        except OSError as exc:
            self._server.stop()
            raise ConfigError(f"cannot start the Foxglove server on {HOST}:{port} ({exc.strerror or exc})") from None
        self.port = self._front.port
        self.queue_size = queue_size
        self.dropped = 0
        self.errors: dict[str, str] = {}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="foxglove-view", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.port}"

    def declare(self, topic: str, payload) -> None:
        """Create a topic's channel now, with the schema `payload` (any message of its type) is recorded with.
        Declared after the server started, a client may not get it (see the module's notes)."""
        from foxglove import Channel, Schema

        if topic not in self._channels:
            spec = schema_for(payload)
            self._channels[topic] = Channel(
                topic,
                schema=Schema(name=spec.name, encoding=spec.encoding, data=spec.data),
                message_encoding=spec.message_encoding,
                context=self._context,
            )

    def log(self, msg: Logged) -> None:
        """Queue a message to publish; never blocks (a full queue drops it)."""
        if msg.topic in LATCHED:
            self._latched[msg.topic] = msg
        if self._queue.qsize() >= self.queue_size:
            self.dropped += 1
            return
        self._queue.put(msg)

    def close(self) -> None:
        self._queue.put(_STOP)
        self._thread.join(5.0)
        self._front.close()
        self._server.stop()

    def _run(self) -> None:
        while True:
            msg = self._queue.get()
            if msg is _STOP:
                return
            try:
                if msg.topic not in self._channels:
                    self.declare(msg.topic, msg.payload)
                self._channels[msg.topic].log(encode(msg.payload), log_time=int(msg.log_time_ns))
            except (ValueError, TypeError) as exc:  # a message the file would refuse too: counted, not fatal
                self.errors.setdefault(msg.topic, str(exc))


_EXAMPLES = {
    "joints": JointSample(0, (), np.zeros(0)),
    "pose": PoseSample(0, "", np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0])),
    "image": ImageSample(0, "", b""),
}
_EVENTS = {T.EPISODE: "teleprev.EpisodeEvent", T.MODE: "teleprev.ModeSwitch", T.DEVICE_EVENT: "teleprev.DeviceEvent",
           T.OPERATOR: "teleprev.OperatorEvent", T.STEP_REPORT: "teleprev.StepReport"}


def session_channels(device_streams) -> dict[str, object]:
    """The topics of a live recording, each with a payload of its type: the devices' streams (StreamSpec),
    the pipeline's, /tf, the events and the robot description."""
    out: dict[str, object] = {
        spec.topic: _EXAMPLES[spec.payload] for spec in device_streams if spec.payload in _EXAMPLES
    }
    out[ROBOT_DESCRIPTION] = RobotDescription(0, "")
    out[T.TF] = TransformsSample(0, ())
    for topic in (T.RETARGETED, T.CORRECTED, T.ARM_TARGET, T.COMMAND_ARM, T.COMMAND_HAND):
        out[topic] = _EXAMPLES["joints"]
    for topic, schema in _EVENTS.items():
        out[topic] = Event(0, schema)
    return out


def file_channels(path: Path) -> dict[str, object]:
    """The topics of a recorded session, each with its first message's payload (its schema)."""
    from teleprev.session.reader import SessionReader

    out: dict[str, object] = {}
    with SessionReader(path) as reader:
        for topic in reader.topics:
            first = next(iter(reader.messages([topic])), None)
            if first is not None:
                out[topic] = first.payload
    return out


def stream_session(view: FoxgloveView, path: Path, start_ns: int | None, stop_ns: int | None, speed: float,
                   ready, stop: threading.Event) -> None:
    """Publish a recorded session's messages logged in [start_ns, stop_ns) at `speed` x their recorded
    pace, once `ready()` (the replay starts playing), until `stop` is set; the robot description first."""
    from teleprev.session.reader import SessionReader

    with SessionReader(path) as reader:
        if ROBOT_DESCRIPTION in reader.topics:
            for msg in reader.messages([ROBOT_DESCRIPTION]):
                view.log(msg)
        while not ready():
            if stop.wait(0.02):
                return
        started, first = time.perf_counter(), None
        topics = [t for t in reader.topics if t != ROBOT_DESCRIPTION]
        for msg in reader.messages(topics, start_ns, stop_ns):
            if stop.is_set():
                return
            first = msg.log_time_ns if first is None else first
            due = (msg.log_time_ns - first) / 1e9 / speed - (time.perf_counter() - started)
            if due > 0:
                time.sleep(due)
            view.log(msg)
