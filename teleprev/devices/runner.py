"""Runs one device on its own thread: connect (and reconnect), read, hand samples on, watch for gaps.

    runner = DeviceRunner(device, sink, clock)   # sink(sample, receive_ns): the session loop's queue
    runner.start(); ...; runner.stats(); runner.stop()

Whatever a device does (fails to open, raises from read(), goes quiet, sends garbage) stays inside its
runner: the runner records it as a teleprev.DeviceEvent on /events/device and keeps trying, so the other
devices keep recording. Events:
    connected      the device opened
    error          connect() or read() raised (message says what): the device failed
    disconnected   the device was closed after an error; reconnect attempts follow every reconnect_s
    gap            no sample for gap_s; since_ns = receive time of the last sample (or of connecting)
    recovered      samples again after a gap; since_ns = the gap's since_ns
    skipped        input the device or the runner counted and skipped since the last such event (at most
                   one a second): the device's counters() and samples with non-finite values or a
                   non-unit quaternion, which never reach the session ("invalid_samples"); counters
                   named "lost_..." are input lost before it was read ("lost 40 to socket overruns")
"""

from __future__ import annotations

import statistics
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import Actuator, Device
from teleprev.errors import DeviceError, DeviceStartError, describe_exception
from teleprev.messages import Event, JointSample, PoseSample, Sample
from teleprev.thread_priority import raise_this_thread

Sink = Callable[[Sample, int], None]

_LATENCY_WINDOW = 512  # samples the latency median/max are taken over
_COUNTER_CHECK_NS = 1_000_000_000  # how often skipped-garbage counters are turned into error events
_FIRST_SAMPLE_GRACE_S = 1.0  # a device just opened may take this long for its first sample


def sample_is_valid(sample: Sample) -> bool:
    """Finite joint values; a finite position and a unit quaternion for a pose. Other payloads pass."""
    p = sample.payload
    if isinstance(p, JointSample):
        return bool(np.all(np.isfinite(np.asarray(p.positions, dtype=float))))
    if isinstance(p, PoseSample):
        q = np.asarray(p.orientation, dtype=float)
        return bool(np.all(np.isfinite(p.position)) and np.all(np.isfinite(q)) and abs(float(q @ q) - 1.0) < 1e-6)
    return True


def default_gap_s(nominal_hz: float) -> float:
    """Five nominal periods, at least 0.25 s."""
    return max(0.25, 5.0 / nominal_hz) if nominal_hz > 0 else 1.0


@dataclass(frozen=True)
class RunnerStats:
    """A snapshot of one device's runner, for the CLI and the terminal preview."""

    name: str
    kind: str
    state: str  # connecting | ok | gap | error | stopped
    received: int  # samples handed to the sink
    errors: int  # connect/read failures plus skipped garbage
    rate_hz: float  # measured rate of the device's first stream (sliding window)
    nominal_hz: float
    latency_ms: float  # receive - acquisition stamp: median over the last samples
    latency_max_ms: float
    last_receive_ns: int | None
    last_error: str
    connects: int
    gaps: int
    sink_errors: int  # samples and events the sink raised on (lost to the session)
    skipped: dict[str, int] = field(default_factory=dict)  # the device's own counters (malformed, NaN, ...)
    topics: dict[str, int] = field(default_factory=dict)  # samples per topic
    start_failure: str = ""  # why the device cannot start at all ("": it could, or may yet)

    @property
    def lost_input(self) -> int:
        return lost_input(self.skipped)


def lost_input(counters: dict[str, int]) -> int:
    """Input a device knows it lost before reading it, from its "lost_" counters: a sequence gap and a
    socket overrun may be the same frame, so the larger of the two, plus what its queue pushed out."""
    return (max(counters.get("lost_socket_overruns", 0), counters.get("lost_sequence_gaps", 0))
            + sum(v for k, v in counters.items()
                  if k.startswith("lost_") and k not in ("lost_socket_overruns", "lost_sequence_gaps")))


class DeviceRunner:
    def __init__(
        self,
        device: Device,
        sink: Sink,
        clock: SessionClock,
        reconnect_s: float = 1.0,
        gap_s: float | None = None,
        read_timeout_s: float = 0.05,
        rate_window_s: float = 2.0,
    ):
        self.device = device
        self.sink = sink
        self.clock = clock
        self.reconnect_s = reconnect_s
        streams = device.streams()
        self.primary_topic = streams[0].topic if streams else ""
        self.nominal_hz = streams[0].rate_hz if streams else 0.0
        fastest = max((s.rate_hz for s in streams), default=0.0)
        self.gap_ns = int((default_gap_s(fastest) if gap_s is None else gap_s) * 1e9)
        self.read_timeout_s = min(read_timeout_s, self.gap_ns / 2e9)
        self.rate_window_ns = int(rate_window_s * 1e9)

        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.priority = ""  # the reading thread's nice value once it runs, or why it could not be raised
        self.connected = False
        self._state = "connecting"
        self._received = 0
        self._faults = 0
        self._connects = 0
        self._gaps = 0
        self._sink_errors = 0
        self._last_error = ""
        self._start_failure = ""  # why the device cannot start (DeviceStartError): the runner has stopped
        self._last_receive: int | None = None
        self._per_topic: dict[str, int] = {}
        self._primary_times: deque[int] = deque()
        self._latencies: deque[int] = deque(maxlen=_LATENCY_WINDOW)
        self._gap_since: int | None = None  # set while in a gap
        self._quiet_since = 0  # receive time of the last sample, or when the device connected
        self._grace_ns = 0
        self._counters: dict[str, int] = {}
        self._counters_reported: dict[str, int] = {}
        self._counters_checked = 0
        self._invalid = 0  # samples the plugin returned with NaN/inf or a non-unit quaternion
        self._device_counts: dict[str, int] = {}  # device.counters() as last read
        self._counter_base: dict[str, int] = {}  # totals from before the device last reset its counters

    @property
    def name(self) -> str:
        return self.device.name

    # ---- lifecycle -----------------------------------------------------------------------------
    def start(self) -> DeviceRunner:
        self._thread = threading.Thread(target=self._run, name=f"device-{self.name}", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        """Stop reading, close the device and wait for the thread (a read() in progress finishes first)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def is_alive(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ---- the device thread -----------------------------------------------------------------------
    def _run(self) -> None:
        # At the session loop's priority: a sample this thread has not handed on ages behind busy processes.
        self.priority = raise_this_thread(thread=f"device {self.name}'s runner")
        try:
            while not self._stop.is_set():
                if not self.connected:
                    self._connect()
                    continue
                try:
                    samples = self.device.read(self.read_timeout_s)
                except Exception as exc:  # a plugin bug must not end the thread either
                    self._fault("read", exc)
                    continue
                now = self.clock.now_ns()
                if samples:
                    self._deliver(samples, now)
                self._check_gap(now)
                self._check_counters(now)
        finally:
            self._check_counters(self.clock.now_ns(), force=True)  # what was skipped since the last report
            self._close()
            with self._lock:
                self._state = "stopped"

    def _connect(self) -> None:
        try:
            self.device.connect()
        except DeviceStartError as exc:
            self._cannot_start(exc)
            return
        except Exception as exc:
            self._fault("connect", exc)
            return
        now = self.clock.now_ns()
        with self._lock:
            self.connected = True
            self._connects += 1
            if self._last_receive is None:  # no data yet: give the first sample a little longer
                self._quiet_since = now
                self._grace_ns = max(self.gap_ns, int(_FIRST_SAMPLE_GRACE_S * 1e9))
            self._state = "gap" if self._gap_since is not None else "ok"
        self._emit("connected", now, f"{type(self.device).__name__} opened")

    def _fault(self, during: str, exc: Exception) -> None:
        message = describe_exception(exc)
        now = self.clock.now_ns()
        with self._lock:
            repeated = not self.connected and message == self._last_error
            self._faults += 1
            self._last_error = message
            self._state = "error"
        if not repeated:  # a device that stays unreachable is reported once, not every reconnect_s
            self._emit("error", now, f"{during} failed: {message}")
        if self.connected:
            self._close()
            self._emit("disconnected", self.clock.now_ns(), f"reconnecting every {self.reconnect_s:g} s")
        deadline = time.monotonic() + self.reconnect_s
        while not self._stop.is_set() and time.monotonic() < deadline:
            self._check_gap(self.clock.now_ns())
            self._stop.wait(min(0.05, max(0.0, deadline - time.monotonic())))

    def _cannot_start(self, exc: DeviceStartError) -> None:
        """A device that cannot start (its port taken, its folder not writable): said once, and no retries,
        which would only say it again every reconnect_s."""
        message = describe_exception(exc)
        with self._lock:
            self._faults += 1
            self._last_error = self._start_failure = message
            self._state = "error"
        self._emit("error", self.clock.now_ns(), f"cannot start: {message}")
        self._stop.set()

    def _close(self) -> None:
        with self._lock:
            self.connected = False
        try:
            self.device.disconnect()
        except Exception as exc:  # closing a broken device may fail too; nothing more to do about it
            with self._lock:
                self._last_error = f"disconnect failed: {describe_exception(exc)}"

    def _deliver(self, samples: list[Sample], now: int) -> None:
        valid = [s for s in samples if sample_is_valid(s)]
        if len(valid) < len(samples):
            with self._lock:
                self._invalid += len(samples) - len(valid)
            samples = valid
            if not samples:
                return
        for sample in samples:
            try:
                self.sink(sample, now)
            except Exception:
                with self._lock:
                    self._sink_errors += 1
        with self._lock:
            self._received += len(samples)
            self._last_receive = now
            self._quiet_since = now
            self._grace_ns = self.gap_ns
            for s in samples:
                self._per_topic[s.topic] = self._per_topic.get(s.topic, 0) + 1
                stamp = getattr(s.payload, "stamp_ns", None)
                if stamp is not None:
                    self._latencies.append(now - stamp)
                if s.topic == self.primary_topic:
                    self._primary_times.append(now)
            while self._primary_times and self._primary_times[0] < now - self.rate_window_ns:
                self._primary_times.popleft()
            gap_since, self._gap_since = self._gap_since, None
            if self.connected:
                self._state = "ok"
        if gap_since is not None:
            self._emit("recovered", now, f"data again after {(now - gap_since) / 1e9:.2f} s", since_ns=gap_since)

    def _check_gap(self, now: int) -> None:
        with self._lock:
            if self._gap_since is not None or self._quiet_since == 0 or now - self._quiet_since <= self._grace_ns:
                return
            self._gap_since = self._quiet_since
            self._gaps += 1
            self._primary_times.clear()
            if self.connected:
                self._state = "gap"
            since = self._gap_since
        what = " since connecting" if self._last_receive is None else ""
        self._emit("gap", now, f"no data for {(now - since) / 1e9:.2f} s{what}", since_ns=since)

    def _check_counters(self, now: int, force: bool = False) -> None:
        """Turn the device's skipped-input counters into a "skipped" event, at most once a second."""
        if not force and now - self._counters_checked < _COUNTER_CHECK_NS:
            return
        self._counters_checked = now
        try:
            raw = dict(self.device.counters())
        except Exception:
            raw = dict(self._device_counts)
        for k, last in self._device_counts.items():  # a device reopened starts over: keep the totals running
            if raw.get(k, 0) < last:
                self._counter_base[k] = self._counter_base.get(k, 0) + last
        self._device_counts = raw
        current = {k: self._counter_base.get(k, 0) + raw.get(k, 0) for k in {*raw, *self._counter_base}}
        current = {k: v for k, v in current.items() if v}
        with self._lock:
            if self._invalid:
                current["invalid_samples"] = self._invalid
            self._counters = current
        new = {
            k: v - self._counters_reported.get(k, 0)
            for k, v in current.items()
            if v > self._counters_reported.get(k, 0)
        }
        if new:
            self._counters_reported = current
            lost = ", ".join(
                f"{v} to {k[5:].replace('_', ' ')}" for k, v in sorted(new.items()) if k.startswith("lost_")
            )
            skipped = ", ".join(
                f"{v} {k.replace('_', ' ')}" for k, v in sorted(new.items()) if not k.startswith("lost_")
            )
            self._emit(
                "skipped", now, "; ".join(p for p in (lost and f"lost {lost}", skipped and f"skipped {skipped}") if p)
            )

    def _emit(self, event: str, now: int, message: str = "", since_ns: int | None = None) -> None:
        data = {"device": self.name, "event": event, "message": message}
        if since_ns is not None:
            data["since_ns"] = int(since_ns)
        try:
            self.sink(Sample(topics.DEVICE_EVENT, Event(now, "teleprev.DeviceEvent", data)), now)
        except Exception:
            with self._lock:
                self._sink_errors += 1

    # ---- what the CLI and the preview show --------------------------------------------------------
    def stats(self) -> RunnerStats:
        now = self.clock.now_ns()
        with self._lock:
            times = [t for t in self._primary_times if t >= now - self.rate_window_ns]
            rate = (len(times) - 1) * 1e9 / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
            lat = list(self._latencies)
            skipped = dict(self._counters)
            return RunnerStats(
                name=self.name,
                kind=self.device.kind,
                state=self._state,
                received=self._received,
                errors=self._faults + sum(v for k, v in skipped.items() if not k.startswith("lost_")),
                rate_hz=rate,
                nominal_hz=self.nominal_hz,
                latency_ms=statistics.median(lat) / 1e6 if lat else 0.0,
                latency_max_ms=max(lat) / 1e6 if lat else 0.0,
                last_receive_ns=self._last_receive,
                last_error=self._last_error,
                connects=self._connects,
                gaps=self._gaps,
                sink_errors=self._sink_errors,
                skipped=skipped,
                topics=dict(self._per_topic),
                start_failure=self._start_failure,
            )


class ActuatorPort:
    """What the session loop sends arm/hand commands through: never raises, counts what did not go out.

    A command is dropped (and counted) while the runner has the device closed; a DeviceError from the
    device's send() (a refused or failed command) is counted with its message.
    """

    def __init__(self, device: Actuator, runner: DeviceRunner | None = None):
        self.device = device
        self.runner = runner
        self.sent = 0
        self.dropped_down = 0
        self.failed = 0
        self.last_error = ""

    @property
    def name(self) -> str:
        return self.device.name

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.device.joint_names

    def send(self, command: JointSample) -> bool:
        if self.runner is not None and not self.runner.connected:
            self.dropped_down += 1
            return False
        try:
            if not np.all(np.isfinite(np.asarray(command.positions, dtype=float))):
                raise DeviceError("command has non-finite positions", f"device {self.name!r}")
            self.device.send(command)
        except Exception as exc:
            self.failed += 1
            self.last_error = describe_exception(exc)
            return False
        self.sent += 1
        return True


def cannot_start_lines(stats: dict[str, RunnerStats], plugins: dict[str, str]) -> list[str]:
    """One line per reason devices cannot start at all (the devices sharing a receiver share its reason), from
    each device's runner stats; `plugins` names each device's plugin."""
    by_reason: dict[str, list[str]] = {}
    for name, s in stats.items():
        if s.start_failure:
            by_reason.setdefault(s.start_failure, []).append(name)
    return [f"{'devices' if len(names) > 1 else 'device'} {', '.join(repr(n) for n in names)} "
            f"({', '.join(dict.fromkeys(plugins[n] for n in names))}) cannot start: {reason}"
            for reason, names in by_reason.items()]
