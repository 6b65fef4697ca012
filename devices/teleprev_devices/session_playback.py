"""replay.*: a recorded session's streams played back as a live device, in real time (or scaled).

    [devices.glove]
    plugin = "replay.glove"
    session = "sessions/2025-01-01_pour.mcap"   # relative to the rig file
    device = "glove"           # the recorded device whose streams to play ("": the session's only one
                               # of this kind); or topic = "/glove/right/hand" for one stream
    speed = 1.0
    loop = false

Streams come out under this device's name (/glove/<name>/hand, ...). Each message is due at
connect time + (its log time - the first log time) / speed, and re-stamped on the current session clock
as connect time + (its stamp - the first log time) / speed, so spacing and latency keep their shape.
replay.arm and replay.hand accept commands (so a rig can use them in place of the robot) and count them;
a recording cannot move.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.devices import (
    Actuator,
    ConfigError,
    Device,
    DeviceContext,
    DeviceError,
    ImageSample,
    JointSample,
    Logged,
    Sample,
    SessionError,
    StreamSpec,
    parse_device_topic,
)

_PAYLOAD = {"hand": "joints", "body": "joints", "wrist": "pose", "image": "image", "state": "joints"}


@dataclass
class ReplaySettings:
    session: str = ""
    device: str = ""
    topic: str = ""
    speed: float = 1.0
    loop: bool = False

    def __post_init__(self):
        if not self.session:
            raise ValueError("session is required: the recorded .mcap file to play back")
        if self.device and self.topic:
            raise ValueError("give device or topic, not both")
        if not 0.01 <= self.speed <= 100:
            raise ValueError(f"speed must be 0.01..100, got {self.speed}")


@dataclass(frozen=True)
class _Plan:
    path: Path
    sources: dict[str, str]  # recorded topic -> topic this device publishes
    rates: dict[str, float]  # published topic -> recorded rate
    first_ns: int
    last_ns: int
    joint_names: tuple[str, ...]


def _plan(device: _Replay) -> _Plan:
    from teleprev.devices import SessionReader

    kind, s = device.kind, device.settings
    where = f"[devices.{device.name}]"
    path = Path(s.session).expanduser()
    path = path if path.is_absolute() else Path(device.context.rig_dir) / path
    try:
        with SessionReader(path) as reader:
            recorded = {t: info for t, info in reader.topics.items() if info.message_count > 0}
            mine = {t: parse_device_topic(t) for t in recorded}
            mine = {t: p for t, p in mine.items() if p and p[0] == kind}
            if s.topic:
                if s.topic not in mine:
                    raise ConfigError(f"{s.topic!r} is not a {kind} stream of {path} "
                                      f"({kind} streams there: {', '.join(sorted(mine)) or 'none'})", f"{where}.topic")
                chosen = [s.topic]
            else:
                devices = sorted({p[1] for p in mine.values()})
                if s.device:
                    if s.device not in devices:
                        raise ConfigError(f"no {kind} device {s.device!r} in {path} (recorded {kind} devices: "
                                          f"{', '.join(devices) or 'none'})", f"{where}.device")
                    source = s.device
                elif len(devices) == 1:
                    source = devices[0]
                else:
                    raise ConfigError(f"{path} has {len(devices) or 'no'} {kind} devices ({', '.join(devices)}): "
                                      "say which with device = \"...\"", where)
                chosen = sorted(t for t, p in mine.items() if p[1] == source)
            sources = {t: device.topic(mine[t][2]) for t in chosen}
            infos = [recorded[t] for t in chosen]
            first, last = min(i.first_ns for i in infos), max(i.last_ns for i in infos)
            rates = {}
            for t in chosen:
                i = recorded[t]
                span = (i.last_ns - i.first_ns) / 1e9
                rates[sources[t]] = (i.message_count - 1) / span * s.speed if span > 0 else 0.0
            joint_names: tuple[str, ...] = ()
            if kind in ("arm", "hand"):
                first_msg = next(reader.messages(topics=chosen[:1]), None)
                if first_msg is not None and isinstance(first_msg.payload, JointSample):
                    joint_names = first_msg.payload.names
    except SessionError as exc:
        raise ConfigError(f"cannot play back {path}: {exc.message}", f"{where}.session") from None
    return _Plan(path, sources, rates, first, last, joint_names)


class _Replay(Device[ReplaySettings]):
    def __init__(self, name: str, settings: ReplaySettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.plan = _plan(self)
        self.where = f"device {name!r} (replay of {self.plan.path.name})"
        self._reader = None
        self._messages: Iterator[Logged] | None = None
        self._pending: Logged | None = None
        self._t0 = 0
        self._ended = False

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(t, _PAYLOAD.get(t.rsplit("/", 1)[-1], "joints"), r) for t, r in self.plan.rates.items()]

    def connect(self) -> None:
        from teleprev.devices import SessionReader

        try:
            self._reader = SessionReader(self.plan.path)
        except SessionError as exc:
            raise DeviceError(f"cannot open the session: {exc}", self.where) from None
        self._start(self.context.clock.now_ns())

    def _start(self, t0: int) -> None:
        self._t0 = t0
        self._messages = self._reader.messages(topics=list(self.plan.sources))
        self._pending = None
        self._ended = False

    def disconnect(self) -> None:
        reader, self._reader = self._reader, None
        self._messages = None
        if reader is not None:
            reader.close()

    def _play_ns(self, recorded_ns: int) -> int:
        return self._t0 + int((recorded_ns - self.plan.first_ns) / self.settings.speed)

    def _next(self) -> Logged | None:
        if self._pending is None and not self._ended:
            try:
                self._pending = next(self._messages)
            except StopIteration:
                if self.settings.loop:
                    span = self.plan.last_ns - self.plan.first_ns
                    period = int(1e9 / max(max(self.plan.rates.values(), default=1.0), 1e-3))
                    self._start(self._t0 + int(span / self.settings.speed) + period)
                    return self._next()
                self._ended = True
            except SessionError as exc:
                raise DeviceError(f"the session cannot be read further: {exc}", self.where) from None
        return self._pending

    def read(self, timeout_s: float) -> list[Sample]:
        if self._reader is None:
            raise DeviceError("not connected", self.where)
        clock = self.context.clock
        deadline = clock.now_ns() + int(timeout_s * 1e9)
        out: list[Sample] = []
        while True:
            msg = self._next()
            if msg is None:  # the recording is over: the device goes quiet (a gap)
                time.sleep(max(0.0, (deadline - clock.now_ns()) / 1e9))
                return out
            due = self._play_ns(msg.log_time_ns)
            now = clock.now_ns()
            if due > now:
                if out or due > deadline:
                    if not out:
                        time.sleep(max(0.0, (deadline - now) / 1e9))
                    return out
                time.sleep((due - now) / 1e9)
            self._pending = None
            out.append(Sample(self.plan.sources[msg.topic], self._restamp(msg.payload)))

    def _restamp(self, payload):
        stamp = self._play_ns(payload.stamp_ns)
        if isinstance(payload, ImageSample):
            return dataclasses.replace(payload, stamp_ns=stamp, frame_id=self.name)
        return dataclasses.replace(payload, stamp_ns=stamp)


class _ReplayActuator(_Replay, Actuator[ReplaySettings]):
    def __init__(self, name: str, settings: ReplaySettings, context: DeviceContext):
        super().__init__(name, settings, context)
        self.joint_names = self.plan.joint_names
        self.commands = 0

    def send(self, command: JointSample) -> None:
        if not np.all(np.isfinite(np.asarray(command.positions, dtype=float))):
            raise DeviceError("command refused: non-finite positions", self.where)
        self.commands += 1


class ReplayGlove(_Replay, kind="glove"):
    """replay.glove: a recorded glove's hand pose."""


class ReplaySuit(_Replay, kind="suit"):
    """replay.suit: a recorded suit's wrist (and body, if recorded)."""


class ReplayCamera(_Replay, kind="camera"):
    """replay.camera: a recorded camera's images."""


class ReplayArm(_ReplayActuator, kind="arm"):
    """replay.arm: a recorded arm's joint state; commands are counted."""


class ReplayHand(_ReplayActuator, kind="hand"):
    """replay.hand: a recorded end effector's joint state; commands are counted."""

