"""leap.hand through the real dynamixel-sdk (and pyserial) against the emulated Dynamixel bus on a
pseudo-terminal (teleprev/emulators): a session, the control table as the e-Manual gives it, and each
injected fault stopping the hand's commands with one line naming the motor and what happened."""

from __future__ import annotations

import struct
import time

import dynamixel_sdk as sdk  # the real SDK: scripts/test.sh installs the leap extra (a missing one fails here)
import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext, DeviceRunner
from teleprev.emulators import dynamixel_wire as wire
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.errors import DeviceError
from teleprev_devices import leap
from teleprev_devices.leap import LeapHand, LeapSettings, SdkDynamixelBus, ticks_from_angles
from tests.helpers.hardware import CommandStream, EventLog


@pytest.fixture(scope="module")
def bus():
    with DynamixelBus().start() as b:
        yield b


def settings(bus, **more) -> LeapSettings:
    """leap.hand's settings as the emulator's rig keys give them: the port and where its latency timer is."""
    return LeapSettings(port=bus.port, latency_timer_path=str(bus.latency_timer_path), **more)


class Session:
    def __init__(self, bus, **more):
        self.clock = SessionClock()
        self.hand = LeapHand("hand", settings(bus, **more), DeviceContext(self.clock))
        self.log = EventLog()
        self.runner = DeviceRunner(self.hand, self.log.sink, self.clock, reconnect_s=0.1).start()
        assert self.log.wait(lambda: self.log.count("connected") == 1), self.log.events
        self.stream = CommandStream(self.hand, self.clock, rate_hz=90.0, amplitude=0.3, period_s=2.0,
                                    joints=slice(1, 4)).start()

    def stop(self):
        self.stream.stop()
        self.runner.stop()


@pytest.fixture
def session(bus):
    s = Session(bus)
    yield s
    s.stop()
    bus.operator_clear()


def test_a_hand_session_through_the_sdk(bus, session):
    writes = bus.goal_writes
    time.sleep(1.0)
    assert bus.goal_writes - writes >= 75 and session.stream.failed == 0, session.stream.last_error
    assert session.log.states >= 75 and session.log.count("error") == 0
    m = bus.motors[2]
    assert m.get(wire.OPERATING_MODE) == 5 and m.get(wire.TORQUE_ENABLE) == 1  # current-based position, torque on
    assert m.get(wire.GOAL_CURRENT) == 350 and m.get(wire.POSITION_P_GAIN) == 600
    assert bus.motors[0].get(wire.POSITION_P_GAIN) == 450  # side-to-side joints at 0.75 kP
    # the motors follow the goals, and the state read back is theirs
    q = np.asarray(session.log.last_state.positions)
    assert q[2] > 0.05  # joint 2 flexed by the commands (up to 0.6 rad)
    assert abs(ticks_from_angles(q)[2] - bus.positions()[2]) < 60
    assert bus.corrupt_requests == 0


@pytest.mark.parametrize("fault, said", [
    ("overload", "motor 5: hardware error: overload (Hardware Error Status 0x20); the motor turned its torque off"),
    ("overheating", "motor 5: hardware error: overheating (Hardware Error Status 0x04)"),
    ("input_voltage", "motor 5: hardware error: input voltage error (Hardware Error Status 0x01)"),
    ("silent", "motor 5 did not answer the sync read"),
    ("bad_crc", "sent a corrupted reply to the sync read at address"),
    ("unplug", "the serial port stopped working (adapter unplugged?)"),
])
def test_a_fault_stops_the_commands_and_names_the_motor(bus, session, fault, said):
    log = session.log
    time.sleep(0.2)
    bus.inject(fault, motor=5)
    assert log.wait(lambda: log.count("error") >= 1, timeout_s=3.0), log.events
    first = log.of("error")[0]["message"]
    assert said in first and "\n" not in first, first
    time.sleep(0.1)
    writes = bus.goal_writes
    time.sleep(0.4)
    assert bus.goal_writes == writes  # the hand's commands stopped
    assert session.stream.failed > 0 and session.runner.is_alive()  # the device is kept, and tried again
    bus.operator_clear()
    assert log.wait(lambda: log.count("connected") == 2, timeout_s=5.0), log.events
    assert log.wait(lambda: bus.goal_writes > writes + 20, timeout_s=3.0)  # commanded again


def test_the_control_table_through_the_sdk(bus):
    port = sdk.PortHandler(bus.port)
    ph = sdk.PacketHandler(2.0)
    assert port.openPort() and port.setBaudRate(4_000_000)
    try:
        model, result, error = ph.ping(port, 7)
        assert (model, result, error) == (wire.XC330_M288, sdk.COMM_SUCCESS, 0)
        assert ph.write1ByteTxRx(port, 7, 64, 1) == (sdk.COMM_SUCCESS, 0)  # torque on
        assert ph.write1ByteTxRx(port, 7, 11, 3) == (sdk.COMM_SUCCESS, wire.ACCESS_ERROR)  # EEPROM: refused
        assert ph.write4ByteTxRx(port, 7, 116, 2200) == (sdk.COMM_SUCCESS, 0)
        time.sleep(0.05)
        group = sdk.GroupSyncRead(port, ph, 126, 10)  # present current, velocity and position in one read
        for i in range(16):
            assert group.addParam(i)
        assert group.txRxPacket() == sdk.COMM_SUCCESS
        current, velocity, position = struct.unpack("<hiI", bytes(group.data_dict[7]))
        assert 2048 < position <= 2200 and velocity >= 0 and current > 0
        assert ph.write1ByteTxRx(port, 7, 64, 0) == (sdk.COMM_SUCCESS, 0)
        assert ph.ping(port, 16)[1] == sdk.COMM_RX_TIMEOUT  # no motor 16 on the hand
    finally:
        port.closePort()


def test_a_port_that_is_not_there(tmp_path):
    hand = LeapHand("hand", LeapSettings(port=str(tmp_path / "ttyUSB9")), DeviceContext(SessionClock()))
    with pytest.raises(Exception, match=r"Dynamixel bus .*ttyUSB9: cannot open the serial port"):
        hand.connect()




def test_the_plugin_sets_the_adapters_latency_timer_to_1_ms():
    with DynamixelBus(latency_timer_ms=16).start() as b:
        link = SdkDynamixelBus(b.port, latency_timer=str(b.latency_timer_path))
        link.open()
        try:
            assert b.latency_timer_path.read_text().strip() == "1" and link.latency_timer_ms == 1
            assert link.latency_note == f"USB adapter latency timer 1 ms ({b.latency_timer_path})"
        finally:
            link.close()


def test_set_latency_timer_false_leaves_the_timer_as_it_is():
    """A lab that keeps its adapter's setting (or a bench measuring the default): the plugin only reads the
    timer, says what it costs, and the hand still works at its pace."""
    with DynamixelBus(latency_timer_ms=16).start() as b:
        hand = LeapHand("hand", settings(b, set_latency_timer=False), DeviceContext(SessionClock()))
        hand.connect()
        try:
            assert b.latency_timer_path.read_text().strip() == "16"
            assert hand.notes() == [f"USB adapter latency timer 16 ms: every reply waits up to 16 ms more; set it "
                                    f"to 1 with `echo 1 | sudo tee {b.latency_timer_path}` (left as it is: "
                                    "set_latency_timer = false)"]
            assert len(hand.read(1.0)) == 1
            took = []
            for _ in range(5):
                t = time.monotonic()
                hand.bus.sync_read(list(range(16)), *leap.PRESENT_POSITION)
                took.append(time.monotonic() - t)
            assert np.median(took) > 0.010  # each 16-motor read waits out the timer (about 17 ms; 1.6 ms at 1)
        finally:
            hand.disconnect()


def test_a_latency_timer_it_may_not_set_is_one_line_with_the_command(tmp_path, monkeypatch):
    timer = tmp_path / "ttyUSB0" / "latency_timer"
    timer.parent.mkdir()
    timer.write_text("16\n")

    def refuse(self, *a, **kw):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(type(timer), "write_text", refuse)  # as sysfs answers a user outside dialout/root
    ms, note = leap.set_latency_timer(timer)
    assert ms == 16 and "\n" not in note
    assert note == (f"USB adapter latency timer 16 ms: every reply waits up to 16 ms more; set it to 1 with "
                    f"`echo 1 | sudo tee {timer}` (no permission to write it from here)")
    assert leap.latency_timer_path("/dev/ttyUSB3") == leap.USB_SERIAL_SYSFS / "ttyUSB3" / "latency_timer"


def test_the_sdk_read_sleeps_instead_of_spinning(bus):
    """While the plugin waits for a silent motor (100 ms with the timer at 1 ms), the process's CPU time stays near
    zero."""
    bus.inject("silent", motor=3)
    link = SdkDynamixelBus(bus.port, latency_timer=str(bus.latency_timer_path))
    link.open()
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(5):
            with pytest.raises(DeviceError, match="motor 3 did not answer"):
                link.sync_read([3], 132, 4)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        link.close()
        bus.operator_clear()
    assert wall > 0.15 and cpu < 0.3 * wall, (wall, cpu)  # a busy-wait burns about as much CPU as wall time


def test_a_missed_reply_is_counted_not_a_fault(bus):
    s = Session(bus, miss_limit=50)
    try:
        time.sleep(0.2)
        bus.motors[5].silent = True  # a few reads go unanswered ...
        assert s.log.wait(lambda: s.hand.counters()["read_misses"] >= 2, timeout_s=2.0)
        bus.motors[5].silent = False  # ... then the motor answers again
        time.sleep(0.3)
        assert s.log.count("error") == 0 and s.stream.failed == 0, s.log.events
    finally:
        s.stop()
        bus.operator_clear()


def test_a_reply_the_host_hands_on_late_is_read_not_missed(bus):
    """The motors answer at once but the host's tty layer hands the replies on 45 ms late (a loaded host's
    kernel worker: bench/hardware.py): the read waits for them. The SDK's own 34.6 ms wait missed it."""
    link = SdkDynamixelBus(bus.port, latency_timer=str(bus.latency_timer_path))
    link.open()
    try:
        bus.host_delay_s = 0.045
        t = time.monotonic()
        assert set(link.sync_read(list(range(16)), 132, 4)) == set(range(16))
        assert time.monotonic() - t > 0.045
    finally:
        bus.host_delay_s = 0.0
        link.close()


def test_a_hand_that_stops_answering_faults_within_the_stated_bound(bus):
    """miss_limit (5) reads in a row, each waiting 100 ms for a 16-motor read with the timer at 1 ms (the
    bytes, 2 x 1 ms + 2 ms and leap.HOST_DELAY_MS): 0.5 s, plus a poll."""
    s = Session(bus)
    try:
        time.sleep(0.2)
        t = time.monotonic()
        bus.motors[5].silent = True
        assert s.log.wait(lambda: s.log.count("error") >= 1, timeout_s=3.0), s.log.events
        took = s.log.of("error")[0]["t"] - t
        assert "motor 5 did not answer" in s.log.of("error")[0]["message"]
        wait_s = leap.reply_wait_ms(240 * 10 / leap.BAUDRATE * 1e3, 1) / 1e3
        assert took < 5 * wait_s + 0.2, took  # the bound, with a poll period and a busy host's slack
        assert s.hand.counters()["read_misses"] >= 4
    finally:
        s.stop()
        bus.operator_clear()


def test_a_write_on_connect_whose_reply_is_lost_is_written_again(bus):
    """Motor 13's status packet for the first write on connect (torque off) is lost on the line: the plugin
    writes the same value again instead of refusing the hand."""
    bus.inject("lost_reply", motor=13)
    hand = LeapHand("hand", settings(bus), DeviceContext(SessionClock()))
    try:
        hand.connect()
        assert not bus.motors[13].lose_next  # the lost reply was the connect's
    finally:
        hand.disconnect()
        bus.operator_clear()


def test_a_late_reply_to_an_earlier_read_is_a_named_miss(bus):
    """A 1-byte status packet meant for an earlier read reaches the host during a 4-byte position read: the
    SDK takes it as the answer; the plugin calls it a read miss, not an IndexError."""
    link = SdkDynamixelBus(bus.port, latency_timer=str(bus.latency_timer_path))
    link.open()
    try:
        bus.inject("stale_reply", motor=5)
        with pytest.raises(leap.ReadMiss, match=r"motor 5 answered the sync read at address 132 with \d bytes, not 4"):
            link.sync_read([4, 5, 6], 132, 4)
        assert set(link.sync_read([4, 5, 6], 132, 4)) == {4, 5, 6}  # the next read is whole again
    finally:
        link.close()
        bus.operator_clear()


def _reply_thread_priority(conn) -> None:
    import os

    try:  # as tests/helpers/emulated_rig.py's processes
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(40))
    except PermissionError:
        conn.send(None)
        return
    with DynamixelBus().start() as b:
        conn.send(os.sched_getparam(b._thread.native_id).sched_priority)


def test_the_bus_answers_at_its_process_real_time_priority_never_lower():
    """In an emulator's process at SCHED_FIFO 40 the thread that answers keeps 40 (it lowered itself to 10,
    behind the command path's processes, and read requests up to 45 ms late)."""
    import multiprocessing as mp

    ours, theirs = mp.get_context("fork").Pipe()
    p = mp.get_context("fork").Process(target=_reply_thread_priority, args=(theirs,))
    p.start()
    assert ours.poll(10), "the bus's process did not answer"
    got = ours.recv()
    p.join(5)
    assert got is not None, "SCHED_FIFO is not permitted here: the tests need real-time priority (run as root)"
    assert got == 40
