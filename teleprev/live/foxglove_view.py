"""A live Foxglove view of a recording or a replay: foxglove-sdk's WebSocket server on 127.0.0.1, carrying
every message the session file gets, on the same topics with the same schemas (the robot included:
/robot_description and /tf). Open it in Foxglove with "Open connection", ws://127.0.0.1:<port>.

Publishing never holds up the session: `log()` queues the message (a full queue drops it and counts
it) and one thread encodes and sends. /robot_description is sent once per session, so it is sent again
whenever a client subscribes to it (a Foxglove window opened mid-session still gets the robot).
"""

from __future__ import annotations

import queue
import threading
import time
from pathlib import Path

from teleprev.errors import ConfigError
from teleprev.messages import Logged, RobotDescription
from teleprev.session.codec import encode, schema_for
from teleprev.topics import ROBOT_DESCRIPTION

DEFAULT_PORT = 8765  # Foxglove's usual WebSocket port
HOST = "127.0.0.1"  # loopback only: reach it from another machine through an SSH tunnel
_STOP = object()


class FoxgloveView:
    def __init__(self, port: int = DEFAULT_PORT, queue_size: int = 4096):
        import foxglove
        from foxglove.websocket import ServerListener

        view = self

        class _Listener(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                if channel.topic == ROBOT_DESCRIPTION and view._urdf is not None:
                    view._queue.put(view._urdf)

        if not 0 <= port <= 65535:
            raise ConfigError(f"--foxglove: {port} is not a TCP port (0..65535)")
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(name="teleprev", host=HOST, port=port, context=self._context,
                                                 server_listener=_Listener())
        except Exception as exc:  # foxglove raises its own error types for a port in use or refused
            raise ConfigError(f"cannot start the Foxglove server on {HOST}:{port} ({exc})") from None
        self.port = self._server.port
        self.queue_size = queue_size
        self.dropped = 0
        self.errors: dict[str, str] = {}
        self._urdf: Logged | None = None
        self._channels: dict[str, object] = {}
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._run, name="foxglove-view", daemon=True)
        self._thread.start()

    @property
    def url(self) -> str:
        return f"ws://{HOST}:{self.port}"

    def log(self, msg: Logged) -> None:
        """Queue a message to publish; never blocks (a full queue drops it)."""
        if isinstance(msg.payload, RobotDescription):
            self._urdf = msg
        if self._queue.qsize() >= self.queue_size:
            self.dropped += 1
            return
        self._queue.put(msg)

    def close(self) -> None:
        self._queue.put(_STOP)
        self._thread.join(5.0)
        self._server.stop()

    def _run(self) -> None:
        from foxglove import Channel, Schema

        while True:
            msg = self._queue.get()
            if msg is _STOP:
                return
            try:
                channel = self._channels.get(msg.topic)
                if channel is None:
                    spec = schema_for(msg.payload)
                    channel = self._channels[msg.topic] = Channel(
                        msg.topic, schema=Schema(name=spec.name, encoding=spec.encoding, data=spec.data),
                        message_encoding=spec.message_encoding, context=self._context)
                channel.log(encode(msg.payload), log_time=int(msg.log_time_ns))
            except (ValueError, TypeError) as exc:  # a message the file would refuse too: counted, not fatal
                self.errors.setdefault(msg.topic, str(exc))


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
