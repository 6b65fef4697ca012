"""DeviceRunner: gaps, recovery, faults and reconnects, while the other devices keep streaming."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.devices.contract import Actuator, Device, DeviceContext, StreamSpec
from teleprev.devices.runner import ActuatorPort, DeviceRunner, default_gap_s
from teleprev.errors import DeviceError
from teleprev.messages import Event, JointSample, Sample
from tests.helpers.wait import wait_until


@dataclass
class TickerSettings:
    rate_hz: float = 100.0
    latency_ms: float = 5.0


class Ticker(Device):
    """A device producing one joint sample per period, stamped latency_ms before it is returned.
    Tests switch it quiet (`silent`), broken (`broken`: read raises) and unplugged (connect raises)."""

    kind = "glove"
    Settings = TickerSettings

    def __init__(self, name, settings, context):
        super().__init__(name, settings, context)
        self.topic = topics.device_topic("glove", name, "hand")
        self.silent = threading.Event()
        self.broken = threading.Event()
        self.unplugged = threading.Event()
        self.crash_with: Exception | None = None
        self.open = False
        self.connects = 0

    def streams(self):
        return [StreamSpec(self.topic, "joints", self.settings.rate_hz)]

    def connect(self):
        if self.unplugged.is_set():
            raise DeviceError("no such device", f"device {self.name!r}")
        self.open = True
        self.connects += 1
        self._next = time.monotonic()

    def disconnect(self):
        self.open = False

    def read(self, timeout_s):
        assert self.open, "read() on a closed device"
        if self.crash_with is not None:
            exc, self.crash_with = self.crash_with, None
            raise exc
        if self.broken.is_set():
            raise DeviceError("cable pulled", f"device {self.name!r}")
        wait = self._next - time.monotonic()
        if wait > timeout_s:
            time.sleep(timeout_s)
            return []
        time.sleep(max(0.0, wait))
        self._next += 1.0 / self.settings.rate_hz
        if self.silent.is_set():
            return []
        stamp = self.context.clock.now_ns() - int(self.settings.latency_ms * 1e6)
        return [Sample(self.topic, JointSample(stamp, ("a",), np.zeros(1)))]


class Collector:
    def __init__(self):
        self.items: list[tuple[Sample, int]] = []
        self.lock = threading.Lock()

    def __call__(self, sample, receive_ns):
        with self.lock:
            self.items.append((sample, receive_ns))

    def events(self, device=None):
        return [s.payload.data for s, _ in self.items
                if s.topic == topics.DEVICE_EVENT and (device is None or s.payload.data["device"] == device)]

    def times(self, topic):
        return [t for s, t in self.items if s.topic == topic]


def make(names, clock, sink, **kw):
    ctx = DeviceContext(clock)
    devices = [Ticker(n, TickerSettings(), ctx) for n in names]
    return devices, [DeviceRunner(d, sink, clock, **kw) for d in devices]


def test_default_gap_is_five_periods_but_at_least_a_quarter_second():
    assert default_gap_s(100.0) == 0.25
    assert default_gap_s(10.0) == 0.5


def test_a_quiet_device_gets_a_gap_then_recovered_and_the_other_keeps_streaming():
    clock, sink = SessionClock(), Collector()
    (a, b), runners = make(["a", "b"], clock, sink)
    for r in runners:
        r.start()
    time.sleep(0.3)
    a.silent.set()
    time.sleep(0.6)
    assert runners[0].stats().state == "gap" and runners[1].stats().state == "ok"
    a.silent.clear()
    time.sleep(0.3)
    for r in runners:
        r.stop()

    events = sink.events("a")
    assert [e["event"] for e in events] == ["connected", "gap", "recovered"]
    a_times = sink.times(a.topic)
    gap, recovered = events[1], events[2]
    last_before = max(t for t in a_times if t <= gap["since_ns"])
    assert gap["since_ns"] == last_before  # the gap starts at the last sample that arrived
    assert recovered["since_ns"] == gap["since_ns"]
    silence = np.diff(a_times).max() / 1e9
    assert 0.55 < silence < 0.9
    assert [e["event"] for e in sink.events("b")] == ["connected"]
    b_times = np.array(sink.times(b.topic))
    assert np.diff(b_times).max() < 0.15e9  # b never paused (allowing for a busy machine)
    assert 95 <= len(b_times) <= 125
    s = runners[1].stats()
    assert s.gaps == 0 and s.received == len(b_times)
    assert 90 < s.rate_hz < 110 and s.nominal_hz == 100.0
    assert 4.9 < s.latency_ms < 25 and s.latency_max_ms >= s.latency_ms
    assert runners[0].stats().gaps == 1 and runners[0].stats().state == "stopped"


def test_a_device_that_dies_is_closed_reconnected_and_picked_up_again():
    clock, sink = SessionClock(), Collector()
    (a, b), runners = make(["a", "b"], clock, sink, reconnect_s=0.1)
    for r in runners:
        r.start()
    time.sleep(0.2)
    a.unplugged.set()
    a.broken.set()
    wait_until(lambda: runners[0].stats().state == "error" and not a.open, 5, what="a's error, closed")
    time.sleep(0.3)  # reconnect attempts while unplugged
    a.broken.clear()
    a.unplugged.clear()
    wait_until(lambda: "recovered" in [e["event"] for e in sink.events("a")], 5, what="a recovered")
    for r in runners:
        r.stop()

    kinds = [e["event"] for e in sink.events("a")]
    assert kinds[:3] == ["connected", "error", "disconnected"]
    assert "cable pulled" in sink.events("a")[1]["message"]
    # reconnect attempts fail while unplugged: reported once, not once per attempt
    connect_errors = [e for e in sink.events("a") if e["event"] == "error" and "connect failed" in e["message"]]
    assert len(connect_errors) == 1 and "no such device" in connect_errors[0]["message"]
    assert kinds.index("gap") < kinds.index("connected", 1) < kinds.index("recovered")
    assert a.connects == 2 and not a.open  # closed after stop()
    stats = runners[0].stats()
    assert stats.connects == 2 and stats.errors >= 3 and "no such device" in stats.last_error
    assert [e["event"] for e in sink.events("b")] == ["connected"]
    assert np.diff(sink.times(b.topic)).max() < 0.15e9


def test_a_plugin_bug_in_read_does_not_end_the_thread():
    clock, sink = SessionClock(), Collector()
    (a,), (runner,) = make(["a"], clock, sink, reconnect_s=0.05)
    a.crash_with = ValueError("index out of range in the parser")
    runner.start()
    time.sleep(0.3)
    runner.stop()
    events = sink.events("a")
    assert events[1]["event"] == "error" and "ValueError: index out of range" in events[1]["message"]
    assert runner.stats().received > 10 and not runner.is_alive()


def test_what_the_sink_refuses_is_counted_in_the_stats_and_the_device_keeps_streaming():
    clock, kept, offered = SessionClock(), Collector(), []

    def sink(sample, receive_ns):
        offered.append(sample)
        if len(offered) % 2:
            raise RuntimeError("queue full")  # every other sample or event
        kept(sample, receive_ns)

    (a,), (runner,) = make(["a"], clock, sink)
    runner.start()
    time.sleep(0.3)
    runner.stop()
    stats = runner.stats()
    assert stats.sink_errors == len(offered) - len(kept.items) > 5 and len(kept.times(a.topic)) > 5
    assert stats.state == "stopped" and stats.errors == 0 and stats.gaps == 0


def test_a_device_that_never_opens_is_reported_once_and_stops_promptly():
    clock, sink = SessionClock(), Collector()
    (a,), (runner,) = make(["a"], clock, sink, reconnect_s=0.05)
    a.unplugged.set()
    runner.start()
    time.sleep(0.3)
    t = time.monotonic()
    runner.stop()
    assert time.monotonic() - t < 0.2
    s = runner.stats()
    assert s.state == "stopped" and s.received == 0 and s.errors >= 4 and s.connects == 0
    assert [e["event"] for e in sink.events("a")] == ["error"]


class Motor(Actuator):
    kind = "arm"
    joint_names = ("joint1",)

    def __init__(self):
        super().__init__("arm", None, DeviceContext(SessionClock()))
        self.sent = []

    def streams(self):
        return [StreamSpec("/arm/arm/state", "joints", 100.0)]

    def connect(self):
        pass

    def read(self, timeout_s):
        return []

    def send(self, command):
        if command.positions[0] > 1.0:
            raise DeviceError("outside the limits", "arm")
        self.sent.append(command)


def test_actuator_port_never_raises_and_counts_what_did_not_go_out():
    motor = Motor()
    clock = SessionClock()
    runner = DeviceRunner(motor, lambda s, t: None, clock)
    port = ActuatorPort(motor, runner)
    cmd = JointSample(0, ("joint1",), np.array([0.5]))
    assert port.send(cmd) is False and port.dropped_down == 1  # not connected yet
    runner.start()
    wait_until(lambda: runner.connected, 5, what="the runner connected")
    assert port.send(cmd) is True
    assert port.send(JointSample(0, ("joint1",), np.array([2.0]))) is False
    assert port.send(JointSample(0, ("joint1",), np.array([np.nan]))) is False
    runner.stop()
    assert (port.sent, port.failed, len(motor.sent)) == (1, 2, 1)
    assert "outside the limits" in port.last_error or "non-finite" in port.last_error


def test_events_carry_the_device_event_schema():
    clock, sink = SessionClock(), Collector()
    (a,), (runner,) = make(["a"], clock, sink)
    runner.start()
    time.sleep(0.05)
    runner.stop()
    sample = next(s for s, _ in sink.items if s.topic == topics.DEVICE_EVENT)
    assert isinstance(sample.payload, Event) and sample.payload.schema == "teleprev.DeviceEvent"
    schema = topics.EVENT_SCHEMAS["teleprev.DeviceEvent"]
    assert set(sample.payload.data) <= set(schema["properties"]) and set(schema["required"]) <= set(sample.payload.data)


def test_a_device_dying_mid_session_leaves_a_gap_event_in_the_file_and_the_others_complete(tmp_path):
    from teleprev.live.core.loop import SessionLoop
    from teleprev.session.reader import SessionReader
    from teleprev.session.recorder import Recorder

    clock = SessionClock()
    recorder = Recorder(tmp_path / "s.mcap").start()
    loop = SessionLoop(clock, recorder.log)
    loop.start()
    (a, b), runners = make(["a", "b"], clock, loop.sink, reconnect_s=0.1)
    for r in runners:
        r.start()
    time.sleep(0.3)
    a.unplugged.set()
    a.broken.set()  # dies and stays away
    time.sleep(0.6)
    for r in runners:
        r.stop()
    loop.stop()
    recorder.close()
    b_received = runners[1].stats().received

    with SessionReader(tmp_path / "s.mcap") as reader:
        events = [m.payload.data for m in reader.messages(topics=[topics.DEVICE_EVENT])]
        b_logged = [m for m in reader.messages(topics=[b.topic])]
        a_logged = [m for m in reader.messages(topics=[a.topic])]
    a_events = [e for e in events if e["device"] == "a"]
    assert [e["event"] for e in a_events][:4] == ["connected", "error", "disconnected", "error"]
    gap = next(e for e in a_events if e["event"] == "gap")
    # since_ns is when a's last sample arrived (its log time, give or take the loop's 1 ns tie-breaks)
    assert 0 <= a_logged[-1].log_time_ns - gap["since_ns"] < 1000
    assert len(b_logged) == b_received and b_received > 80  # every sample of b is in the file
    assert np.diff([m.log_time_ns for m in b_logged]).max() < 0.15e9


class Faulty(Ticker):
    """Every third sample carries a NaN; every fifth is a pose with a non-unit quaternion."""

    def read(self, timeout_s):
        from teleprev.messages import PoseSample

        out = super().read(timeout_s)
        self.n = getattr(self, "n", 0) + len(out)
        if out and self.n % 3 == 0:
            return [Sample(self.topic, JointSample(out[0].payload.stamp_ns, ("a",), np.array([np.nan])))]
        if out and self.n % 5 == 0:
            return [
                Sample(self.topic, PoseSample(out[0].payload.stamp_ns, "suit", np.zeros(3), np.array([0, 0, 1e3, 1.0])))
            ]
        return out


def test_non_finite_and_non_unit_samples_stop_at_the_plugin_boundary_and_are_counted():
    clock, sink = SessionClock(), Collector()
    device = Faulty("a", TickerSettings(), DeviceContext(clock))
    runner = DeviceRunner(device, sink, clock).start()
    time.sleep(0.5)
    runner.stop()
    delivered = [s.payload for s, _ in sink.items if s.topic == device.topic]
    assert delivered and all(np.isfinite(p.positions).all() for p in delivered)
    bad = device.n // 3 + device.n // 5 - device.n // 15
    assert runner.stats().skipped["invalid_samples"] == bad == device.n - len(delivered)
    skipped = [e for e in sink.events("a") if e["event"] == "skipped"]
    assert skipped and skipped[-1]["message"].startswith("skipped") and "invalid samples" in skipped[-1]["message"]
