"""What every sim device shares: its own clock and transport, real-time pacing, and the truth log.

A sim device acquires at a fixed rate on its own clock, stamps each acquisition with device time, and
"delivers" it after a transport delay; `read()` sleeps until the next delivery is due (never spins),
converts the device stamps to the session clock with ClockSync, as a hardware plugin would, and records
the true acquisition time of each sample in the rig's TruthLog.
"""

from __future__ import annotations

import dataclasses
import time
import zlib
from abc import abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import PurePath
from typing import Any, ClassVar, TypeVar

import numpy as np

from teleprev.devices import ClockSync, ConfigError, Device, DeviceContext, DeviceError, Sample, StreamSpec
from teleprev_devices.sim.clock import DeviceClock, Transport, TruthLog, TruthRecord, shared_truth

_HANDSHAKE = 4  # hello packets exchanged at connect, so ClockSync has an offset before the first sample
_MAX_BACKLOG_NS = 500_000_000  # acquisitions older than this when read() comes round are dropped


@dataclass
class TimingSettings:
    """Clock and transport of a sim device (the keys every sim device's table accepts)."""

    rate_hz: float = 100.0
    latency_ms: float = 2.0  # minimum transport delay (known to the receiver, as a real device's would be)
    jitter_ms: float = 0.3  # mean extra delay on top (exponential, with rare late packets)
    clock_offset_s: float = 1000.0  # the device clock's lead over the session clock
    clock_drift_ppm: float = 10.0  # how much faster the device clock runs
    seed: int = 0
    truth_log: str = ""  # CSV file of true acquisition times, relative to the rig file ("": memory only)

    def __post_init__(self):
        if not (0 < self.rate_hz <= 2000):
            raise ValueError(f"rate_hz must be in (0, 2000], got {self.rate_hz}")
        for key in ("latency_ms", "jitter_ms"):  # a second or more is no device's transport
            if not 0 <= getattr(self, key) <= 1000:
                raise ValueError(f"{key} must be in [0, 1000] ms, got {getattr(self, key)}")
        if not abs(self.clock_drift_ppm) <= 1000:
            raise ValueError(f"clock_drift_ppm must be within ±1000, got {self.clock_drift_ppm}")
        if not abs(self.clock_offset_s) <= 1e6:  # a device clock days apart from the host's is still fine
            raise ValueError(f"clock_offset_s must be within ±1e6 s, got {self.clock_offset_s}")
        log = PurePath(self.truth_log)
        if self.truth_log and (log.is_absolute() or ".." in log.parts):  # a rig file never writes outside its folder
            raise ValueError(f"truth_log must be a path inside the rig file's folder, got {self.truth_log!r}")


T = TypeVar("T", bound=TimingSettings)


def timing(rate_hz: float, latency_ms: float, jitter_ms: float, clock_offset_s: float,
           clock_drift_ppm: float) -> Callable[[type[T]], type[T]]:
    """Makes a TimingSettings subclass a dataclass whose timing keys default to this device's values."""
    defaults = {"rate_hz": rate_hz, "latency_ms": latency_ms, "jitter_ms": jitter_ms,
                "clock_offset_s": clock_offset_s, "clock_drift_ppm": clock_drift_ppm}

    def apply(cls: type[T]) -> type[T]:
        # Re-annotating an inherited field gives it a new default and keeps its place in the field order.
        cls.__annotations__ = {**{key: "float" for key in defaults}, **cls.__dict__.get("__annotations__", {})}
        for key, value in defaults.items():
            setattr(cls, key, value)
        return dataclass(cls)

    return apply


class NoiseBlock:
    """Gaussian sensor noise of `dims` values per sample, drawn a block of samples at a time."""

    def __init__(self, rng: np.random.Generator, std: float, dims: int, block: int = 128):
        self._rng, self._std, self._dims, self._block = rng, std, dims, block
        self._rows: list[np.ndarray] = []

    def next(self) -> np.ndarray:
        if not self._rows:
            self._rows = list(self._rng.normal(0.0, self._std, (self._block, self._dims)))
        return self._rows.pop()


@dataclass
class _Pending:
    true_ns: int
    device_ns: int
    arrive_ns: int
    payload: Any = None  # acquired once true_ns has come


class SimDevice(Device[T]):
    """Base of the sim plugins: one stream at settings.rate_hz, named as they subclass, e.g.
    `class SimGlove(..., kind="glove", stream="hand", payload="joints")`. Subclasses implement
    `_acquire(true_ns)`: the payload acquired at that session time (its stamp is replaced on delivery)."""

    stream: ClassVar[str]  # e.g. "hand": /<kind>/<name>/hand
    payload: ClassVar[str]  # "joints", "pose" or "image"
    acquire_on_time: ClassVar[bool] = False  # wake up at acquisition time (a camera renders "now")

    def __init_subclass__(cls, stream: str = "", payload: str = "", **kwargs: Any):
        super().__init_subclass__(**kwargs)
        if stream:
            cls.stream, cls.payload = stream, payload

    def __init__(self, name: str, settings: T, context: DeviceContext):
        super().__init__(name, settings, context)
        self.stream_topic = self.topic(self.stream)
        self.period_ns = int(round(1e9 / settings.rate_hz))
        self.truth: TruthLog = shared_truth(context.shared)
        if settings.truth_log:
            self.truth.write_to(context.rig_dir / settings.truth_log)
        self._rng = np.random.default_rng([settings.seed, zlib.crc32(name.encode())])
        self._connected = False
        self._pending: deque[_Pending] = deque()

    def where(self, key: str | None = None) -> str:
        return f"[devices.{self.name}]" + (f".{key}" if key else "")

    def bad_setting(self, key: str | None, message: str) -> ConfigError:
        return ConfigError(message, self.where(key))

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.stream_topic, self.payload, self.settings.rate_hz)]

    # ---- the device's own clock ----------------------------------------------------------------
    def connect(self) -> None:
        s = self.settings
        clock = self.context.clock
        self.device_clock = DeviceClock(clock, s.clock_offset_s, s.clock_drift_ppm)
        self.transport = Transport(s.latency_ms, s.jitter_ms, self._rng)
        self.sync = ClockSync(latency_ns=self.transport.min_ns)
        self._open()
        for _ in range(_HANDSHAKE):
            sent = clock.now_ns()
            device_ns = self.device_clock.device_ns(sent)
            self._sleep_until(sent + self.transport.delay_ns())
            self.sync.observe(device_ns, clock.now_ns())
        self._next_device_ns = self.device_clock.device_ns(clock.now_ns())
        self._last_arrive = 0
        self._pending.clear()
        self._connected = True

    def _open(self) -> None:
        """Subclass hook run at connect, before the clock handshake."""

    def disconnect(self) -> None:
        self._connected = False  # a read() in progress on another thread returns at its next wake-up
        self.truth.flush()

    def _sleep_until(self, session_ns: int) -> None:
        dt = (session_ns - self.context.clock.now_ns()) / 1e9
        if dt > 0:
            time.sleep(dt)

    def _schedule(self, now: int) -> None:
        """Queue acquisitions up to the first one still in the future."""
        while not self._pending or self._pending[-1].true_ns <= now:
            true_ns = self.device_clock.session_ns(self._next_device_ns)
            if now - true_ns > _MAX_BACKLOG_NS:  # nobody read for a while: the device's buffer overflowed
                skip = (now - true_ns) // self.period_ns
                self._next_device_ns += int(skip) * self.period_ns
                continue
            arrive = max(true_ns + self.transport.delay_ns(), self._last_arrive)  # in order, like USB/TCP
            self._last_arrive = arrive
            self._pending.append(_Pending(true_ns, self._next_device_ns, arrive))
            self._next_device_ns += self.period_ns

    def read(self, timeout_s: float) -> list[Sample]:
        if not self._connected:
            raise DeviceError("not connected", f"device {self.name!r}")
        clock = self.context.clock
        deadline = clock.now_ns() + int(max(timeout_s, 0.0) * 1e9)
        while True:
            if not self._connected:
                return []
            now = clock.now_ns()
            self._schedule(now)
            for p in self._pending:
                if p.true_ns > now:
                    break
                if p.payload is None:
                    p.payload = self._acquire(p.true_ns)
            out: list[Sample] = []
            # `now` is when this pass woke up: what had arrived by then was received then (making the
            # payloads is the simulator's own work, not part of the transport).
            while self._pending and self._pending[0].arrive_ns <= now and self._pending[0].payload is not None:
                p = self._pending.popleft()
                receive = now
                stamp = self.sync.observe(p.device_ns, receive)
                out.append(Sample(self.stream_topic, dataclasses.replace(p.payload, stamp_ns=stamp)))
                self.truth.add(TruthRecord(self.stream_topic, stamp, p.true_ns, p.device_ns, receive))
            if out:
                return out
            wake = self._pending[0].arrive_ns
            if self.acquire_on_time:
                wake = min(wake, next(p.true_ns for p in self._pending if p.payload is None))
            if now >= deadline:
                return []
            self._sleep_until(min(wake, deadline))

    @abstractmethod
    def _acquire(self, true_ns: int) -> Any:
        """The payload (a JointSample, PoseSample or ImageSample) acquired at session time true_ns."""
