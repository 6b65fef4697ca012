"""Every connect failure says why: an exception whose text is empty (TimeoutError(), a DeviceError with no
message) is named by its type, where it happened and what it came from; a device whose connect() has not
returned when the connect timeout ends (the sim camera building its renderer under heavy load) says so.
It ended in `connect failed: ` and nothing after."""

from __future__ import annotations

import time

from teleprev.errors import DeviceError, describe_exception
from teleprev.messages import Event
from tests.helpers.wait import wait_until


def test_an_empty_exception_is_named_by_its_type_place_and_cause():
    assert describe_exception(TimeoutError()) == "TimeoutError"
    assert describe_exception(DeviceError("", "device 'cam'")) == "DeviceError in device 'cam'"
    try:
        try:
            raise TimeoutError()
        except TimeoutError as inner:
            raise DeviceError("") from inner
    except DeviceError as exc:
        assert describe_exception(exc) == "DeviceError (from TimeoutError)"
    assert describe_exception(OSError(5, "I/O error")) == "OSError: [Errno 5] I/O error"
    assert describe_exception(DeviceError("gone", "device 'arm'")) == "device 'arm': gone"


def test_a_connect_raising_an_empty_exception_is_reported_with_its_type():
    from teleprev.clock import SessionClock
    from teleprev.devices.contract import DeviceContext
    from teleprev.devices.runner import DeviceRunner
    from tests.devices.test_runner import Ticker, TickerSettings

    events = []
    device = Ticker("glove", TickerSettings(), DeviceContext(SessionClock()))
    device.connect = lambda: (_ for _ in ()).throw(TimeoutError())
    runner = DeviceRunner(device, lambda sample, now: events.append(sample.payload), SessionClock()).start()
    try:
        wait_until(lambda: runner.stats().last_error, 5.0, what="the connect failure")
    finally:
        runner.stop()
    assert runner.stats().last_error == "TimeoutError"
    said = [e.data["message"] for e in events if isinstance(e, Event) and e.data["event"] == "error"]
    assert said == ["connect failed: TimeoutError"]


def test_a_connect_still_running_at_the_timeout_says_so(tmp_path, monkeypatch):
    """The sim camera's connect() outlasts the connect timeout (as under heavy load): its line says it was
    still connecting, not `connect failed: ` with no reason."""
    from teleprev.live.record.session import LiveSession, RecordOptions
    from teleprev_devices.sim.camera import SimCamera

    opened = SimCamera._open
    monkeypatch.setattr(SimCamera, "_open", lambda self: (time.sleep(3.0), opened(self)))
    session = LiveSession(RecordOptions(out=tmp_path / "s.mcap", connect_timeout_s=0.5))
    try:
        session.start()
        problems = session.wait_connected()
    finally:
        session.stop()
    (line,) = [p for p in problems if "cam_front" in p]
    assert line == ("device 'cam_front' (sim.camera) sent nothing within 0.5 s: still connecting: its connect() had "
                    "not returned after 0.5 s (a busy machine? raise --connect-timeout)")
