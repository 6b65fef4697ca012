"""The emulators against the manufacturers' documents, through the real SDKs: one test per documented behaviour
(the source is named in each test's docstring). bench/hardware.py counts the ones that pass as
`emulator_conformance`."""

from __future__ import annotations

import statistics
import time

import dynamixel_sdk as sdk  # the real SDKs: scripts/test.sh installs the leap and xarm extras
import numpy as np
import pytest
from xarm.wrapper import XArmAPI

from teleprev.emulators import dynamixel_wire as dxl
from teleprev.emulators import xarm_wire as xw
from teleprev.emulators.dynamixel_bus import DynamixelBus
from teleprev.emulators.xarm_controller import XArmController


# ---- the Dynamixel bus (e-Manual: Protocol 2.0, XC330-M288-T control table; FTDI AN232B-04) --------------
@pytest.fixture
def bus():
    with DynamixelBus(latency_timer_ms=1).start() as b:
        port, ph = sdk.PortHandler(b.port), sdk.PacketHandler(2.0)
        assert port.openPort() and port.setBaudRate(4_000_000)
        yield b, port, ph
        port.closePort()


def test_dxl_model_number_is_the_xc330_m288s(bus):
    """e-Manual XC330-M288-T: Model Number (0) = 1,240."""
    _, port, ph = bus
    assert ph.ping(port, 3) == (1240, sdk.COMM_SUCCESS, 0)


def test_dxl_power_on_values_are_the_control_tables(bus):
    """e-Manual XC330-M288-T, Initial Value column."""
    _, port, ph = bus
    read = {name: ph.read2ByteTxRx(port, 5, address)[0] if size == 2 else ph.read1ByteTxRx(port, 5, address)[0]
            for name, address, size in (("current limit", 38, 2), ("return delay", 9, 1), ("status return", 68, 1),
                                        ("P", 84, 2), ("I", 82, 2), ("D", 80, 2), ("operating mode", 11, 1))}
    assert read == {"current limit": 2352, "return delay": 250, "status return": 2, "P": 1100, "I": 0, "D": 500,
                    "operating mode": 3}


@pytest.mark.parametrize("what, address, size, value, error", [
    ("operating mode 2 (no such mode)", 11, 1, 2, dxl.DATA_RANGE_ERROR),
    ("present position (read only)", 132, 4, 100, dxl.ACCESS_ERROR),
    ("goal current above the current limit", 102, 2, 2400, dxl.DATA_LIMIT_ERROR),
    ("half of goal position", 116, 2, 100, dxl.DATA_LENGTH_ERROR),
])
def test_dxl_a_write_the_table_does_not_allow_is_refused(bus, what, address, size, value, error):
    """e-Manual Protocol 2.0 status errors: Data Range, Access, Data Limit, Data Length."""
    _, port, ph = bus
    write = {1: ph.write1ByteTxRx, 2: ph.write2ByteTxRx, 4: ph.write4ByteTxRx}[size]
    assert write(port, 2, address, value) == (sdk.COMM_SUCCESS, error), what


def test_dxl_eeprom_is_written_only_with_the_torque_off(bus):
    """e-Manual control table: "Data in the EEPROM Area can only be written when Torque Enable(64) is 0"."""
    _, port, ph = bus
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 11, 5) == (sdk.COMM_SUCCESS, dxl.ACCESS_ERROR)
    assert ph.write1ByteTxRx(port, 2, 64, 0) == (sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 11, 5) == (sdk.COMM_SUCCESS, 0)


def test_dxl_broadcast_ping_answers_every_motor(bus):
    """e-Manual Protocol 2.0 Ping: to the broadcast ID every device answers."""
    _, port, ph = bus
    found, result = ph.broadcastPing(port)
    assert result == sdk.COMM_SUCCESS and sorted(found) == list(range(16))
    assert all(model == 1240 for model, _firmware in found.values())


def test_dxl_bulk_read_reads_different_items_of_different_motors(bus):
    """e-Manual Protocol 2.0 Bulk Read."""
    _, port, ph = bus
    group = sdk.GroupBulkRead(port, ph)
    assert group.addParam(1, 132, 4) and group.addParam(7, 38, 2)
    assert group.txRxPacket() == sdk.COMM_SUCCESS
    assert group.getData(1, 132, 4) == 2048 and group.getData(7, 38, 2) == 2352


def test_dxl_fast_sync_read_is_one_packet(bus):
    """e-Manual Protocol 2.0 Fast Sync Read: one status packet with every device's part."""
    b, port, ph = bus
    group = sdk.GroupSyncRead(port, ph, 132, 4)
    for i in range(16):
        group.addParam(i)
    assert group.fastSyncRead() == sdk.COMM_SUCCESS
    assert [group.getData(i, 132, 4) for i in range(16)] == [2048] * 16
    b.inject("silent", motor=9)  # the packet is cut short where a motor does not speak
    assert group.fastSyncRead() != sdk.COMM_SUCCESS


def test_dxl_a_broadcast_write_is_done_by_all_and_answered_by_none(bus):
    """e-Manual Protocol 2.0: no Status Packet for an instruction to the broadcast ID (but Ping and reads)."""
    _, port, ph = bus
    assert ph.write1ByteTxRx(port, sdk.BROADCAST_ID, 65, 1)[0] == sdk.COMM_SUCCESS  # the SDK expects no reply
    assert [ph.read1ByteTxRx(port, i, 65)[0] for i in (0, 8, 15)] == [1, 1, 1]


def test_dxl_a_reboot_brings_back_the_ram_and_keeps_the_eeprom(bus):
    """e-Manual Reboot / control table: the RAM area (64 and up) starts from its initial values."""
    _, port, ph = bus
    assert ph.write1ByteTxRx(port, 4, 11, 5) == (sdk.COMM_SUCCESS, 0)  # EEPROM
    assert ph.write2ByteTxRx(port, 4, 84, 600) == (sdk.COMM_SUCCESS, 0)  # RAM
    assert ph.write1ByteTxRx(port, 4, 64, 1) == (sdk.COMM_SUCCESS, 0)
    assert ph.reboot(port, 4) == (sdk.COMM_SUCCESS, 0)
    assert ph.read2ByteTxRx(port, 4, 84)[0] == 1100 and ph.read1ByteTxRx(port, 4, 64)[0] == 0
    assert ph.read1ByteTxRx(port, 4, 11)[0] == 5


def test_dxl_status_return_level_1_answers_reads_only(bus):
    """e-Manual Status Return Level (68): 1 = status packets for PING and READ only."""
    _, port, ph = bus
    assert ph.write1ByteTxOnly(port, 6, 68, 1) == sdk.COMM_SUCCESS
    time.sleep(0.01)
    assert ph.write1ByteTxRx(port, 6, 65, 1)[0] == sdk.COMM_RX_TIMEOUT  # done, but not answered
    assert ph.read1ByteTxRx(port, 6, 65) == (1, sdk.COMM_SUCCESS, 0)


def test_dxl_motors_set_to_another_baud_rate_say_nothing(bus):
    """e-Manual Baud Rate (8): a device talks at its own rate; the LEAP Hand's are at 4 Mbps."""
    b, port, ph = bus
    assert port.setBaudRate(1_000_000)
    assert ph.ping(port, 3)[1] == sdk.COMM_RX_TIMEOUT and b.unheard >= 1
    assert port.setBaudRate(4_000_000) and ph.ping(port, 3)[1] == sdk.COMM_SUCCESS


def _sync_read_ms(port, ph, n: int = 12) -> float:
    group = sdk.GroupSyncRead(port, ph, 132, 4)
    for i in range(16):
        group.addParam(i)
    times = []
    for _ in range(n):
        t = time.perf_counter()
        assert group.txRxPacket() == sdk.COMM_SUCCESS
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def test_dxl_each_motor_answers_after_its_return_delay(bus):
    """e-Manual Return Delay Time (9): 2 us per unit, 250 (500 us) at power-on; 16 motors answer in turn."""
    _, port, ph = bus
    slow = _sync_read_ms(port, ph)
    assert slow >= 16 * 0.5  # 16 motors x 500 us, at least
    assert ph.write1ByteTxRx(port, sdk.BROADCAST_ID, 9, 0)[0] == sdk.COMM_SUCCESS
    assert _sync_read_ms(port, ph) < slow - 4


def test_dxl_the_adapters_latency_timer_holds_short_replies():
    """FTDI AN232B-04: a short packet waits for the latency timer (16 ms by default, 1 ms once set)."""
    with DynamixelBus().start() as b:
        port, ph = sdk.PortHandler(b.port), sdk.PacketHandler(2.0)
        assert port.openPort() and port.setBaudRate(4_000_000)
        try:
            def ping_ms() -> float:
                times = []
                for _ in range(25):
                    t = time.perf_counter()
                    assert ph.ping(port, 2)[1] == sdk.COMM_SUCCESS
                    times.append((time.perf_counter() - t) * 1e3)
                return statistics.mean(times)

            default = ping_ms()
            b.latency_timer_path.write_text("1\n")  # what `echo 1 > .../latency_timer` does
            fast = ping_ms()
        finally:
            port.closePort()
    assert default - fast > 3.0, (default, fast)  # 16 ms holds a reply 8 ms on average, 1 ms 0.5 ms


# ---- the xArm control box (xarm-python-sdk source; UFactory developer manual) ---------------------------
@pytest.fixture(scope="module")
def box():
    with XArmController(host=None).start() as b:
        yield b


@pytest.fixture
def api(box):
    a = XArmAPI(box.host, is_radian=True)
    assert a.connected
    yield a
    a.disconnect()
    box.operator_clear()


def test_xarm_a_mode_change_leaves_state_5_until_set_state_0(box, api):
    """xarm_ros RobotMsg.msg: state 5, "mode changed, not ready for motion commands"; the SDK's code 9."""
    assert (api.motion_enable(True), api.set_mode(1)) == (0, 0)
    assert api.get_state() == (0, xw.CONFIG_CHANGED)
    assert api.set_servo_angle_j(list(box.angles), is_radian=True) == 9 and not box.arrivals[-1].taken
    assert api.set_state(0) == 0 and api.get_state() == (0, xw.READY)
    assert api.set_servo_angle_j(list(box.angles), is_radian=True) == 0


def test_xarm_set_state_6_is_a_deceleration_stop(box, api):
    """XArmAPI.set_state: 6 = deceleration stop; the arm ends stopped (state 4)."""
    assert (api.motion_enable(True), api.set_mode(0), api.set_state(0)) == (0, 0, 0)
    assert api.set_servo_angle(angle=[0.5, -0.3, -0.2, 0, -0.8, 0], speed=0.5, is_radian=True) == 0
    assert api.set_state(6) == 0 and api.get_state() == (0, xw.STOPPED)
    moved = box.angles.copy()
    time.sleep(0.1)
    assert np.allclose(box.angles, moved)


def test_xarm_position_mode_moves_take_their_time(box, api):
    """set_servo_angle(wait=True), reset(): the arm moves at the requested speed; the SDK waits for state 2."""
    assert (api.motion_enable(True), api.set_mode(0), api.set_state(0)) == (0, 0, 0)
    goal = [0.3, -0.3, -0.3, 0.0, -0.6, 0.2]
    distance = float(np.max(np.abs(np.array(goal) - box.angles)))
    t = time.monotonic()
    assert api.set_servo_angle(angle=goal, speed=1.0, is_radian=True, wait=True) == 0
    assert time.monotonic() - t >= distance / 1.0 and np.allclose(box.angles, goal, atol=1e-6)
    api.reset(wait=True, speed=1.0)
    assert np.allclose(box.angles, 0.0)
    code, pose = api.get_position(is_radian=True)
    assert code == 0 and np.allclose(pose[:3], [207.0, 0.0, 112.0], atol=0.1)  # UFactory: xArm6 zero pose


def test_xarm_set_position_reaches_the_pose(box, api):
    """set_position (register 21, MOVE_LINE): the TCP goes to the pose, in mm and rad."""
    assert (api.motion_enable(True), api.set_mode(0), api.set_state(0)) == (0, 0, 0)
    assert api.set_position(x=300, y=50, z=250, roll=np.pi, pitch=0, yaw=0, speed=200, is_radian=True, wait=True) == 0
    code, pose = api.get_position(is_radian=True)
    assert np.allclose(pose[:3], [300, 50, 250], atol=1.0)


def test_xarm_the_tcp_pose_is_forward_kinematics(box):
    """The TCP pose at the sim home, by FK of our URDF: [291.5, 0, 305.3] mm."""
    fresh = XArmController(host=None)
    assert np.allclose(fresh.pose()[:3], [291.5, 0.0, 305.3], atol=0.1)


def test_xarm_get_joint_states_answers_positions_velocities_efforts(box, api):
    """XArmAPI.get_joint_states: register 42 with a count, 7 floats per row."""
    code, (position, velocity, effort) = api.get_joint_states(is_radian=True)
    assert code == 0 and np.allclose(position[:6], box.angles, atol=1e-6) and len(velocity) == len(effort) == 7


def test_xarm_the_real_time_report_runs_at_100_hz(box):
    """Port 30003 (TCP_REPORT_REAL_PORT): the real-time report, 100 Hz."""
    api = XArmAPI(box.host, is_radian=True, report_type="real")
    seen = []
    api.register_report_callback(lambda r: seen.append(time.monotonic()))
    try:
        time.sleep(1.0)
    finally:
        api.disconnect()
    assert len(seen) >= 60, len(seen)  # 100 Hz, less what a busy host delays
    assert np.allclose(api.angles[:6], box.angles, atol=1e-5)


def _servo(box, api):
    assert (api.motion_enable(True), api.set_mode(1), api.set_state(0)) == (0, 0, 0)
    return np.array(box.angles)


def test_xarm_only_the_latest_target_of_a_servo_cycle_runs(box, api):
    """Servo mode runs the latest target each cycle: a burst is one jump, judged as one (error 24)."""
    q = _servo(box, api)
    before = box.servo.superseded
    for _ in range(8):  # 8 x 0.01 rad within a few ms: each alone is slow, together 0.08 rad in one cycle
        q[0] += 0.01
        api.set_servo_angle_j(list(q), is_radian=True)
    assert box.servo.superseded > before or box.error == xw.SPEED_LIMIT
    assert api.get_err_warn_code()[1][0] == xw.SPEED_LIMIT


def test_xarm_speed_is_judged_on_arrival_not_on_any_stamp(box, api):
    """The box only knows when a target arrived: steps meant for 10 ms each, sent 1 ms apart, are 10x too fast."""
    q = _servo(box, api)
    for _ in range(20):
        q[1] += 0.02  # 2 rad/s at 10 ms, about 5 rad/s at one 4 ms servo cycle: past joint2's pi rad/s
        if api.set_servo_angle_j(list(q), is_radian=True) != 0:
            break
        time.sleep(0.001)
    assert api.get_err_warn_code()[1][0] == xw.SPEED_LIMIT


def test_xarm_flange_speed_over_the_limit_is_error_60(box, api):
    """x_code ControllerError 60: "Linear speed exceeded limit in servo_j mode"."""
    q = _servo(box, api)
    q[:] = [0.0, 0.8, -1.2, 0.0, 0.4, 0.0]  # the flange 0.52 m out
    radius = float(np.hypot(*box.kinematics.flange(q)[:2, 3]))
    box.operator_clear()
    box.angles = q.copy()  # the arm stretched out (as an operator would have moved it)
    assert (api.set_mode(1), api.set_state(0)) == (0, 0)
    omega = 1.25 / radius  # 1.25 m/s at the flange, under pi rad/s at joint1
    assert omega < np.pi
    for k in range(80):  # from rest up to omega over 0.4 s, then on
        q[0] += omega * min(1.0, (k + 1) / 40) * 0.01
        if api.set_servo_angle_j(list(q), is_radian=True) != 0:
            break
        time.sleep(0.01)
    assert api.get_err_warn_code()[1][0] == xw.SERVO_TCP_SPEED
    assert max(j.speed_ratio for j in list(box.judged)[-20:]) < 1.1  # no joint too fast: the flange was


def test_xarm_the_joint_table_of_the_arms_series_is_enforced():
    """x_config.py JOINT_LIMITS, XARM6_X4_1305: joint3 <= 0.174532 rad on an XI1305-series arm (error 23)."""
    with XArmController(host=None, series=1305).start() as b:
        api = XArmAPI(b.host, is_radian=True, check_joint_limit=False)
        try:
            q = _servo(b, api)
            q[2] = 0.18
            assert api.set_servo_angle_j(list(q), is_radian=True) == 1
            assert api.get_err_warn_code()[1][0] == xw.JOINT_LIMIT
        finally:
            api.disconnect()


def test_xarm_every_target_is_stamped_on_arrival(box, api):
    """For the wire-timing bench: arrival time and servo cycle of every target, taken or not."""
    q = _servo(box, api)
    start = len(box.arrivals)
    for _ in range(10):
        api.set_servo_angle_j(list(q), is_radian=True)
        time.sleep(0.005)
    got = list(box.arrivals)[start:]
    assert len(got) == 10 and all(a.taken for a in got)
    stamps = [a.received_ns for a in got]
    assert stamps == sorted(stamps) and all(a.cycle == a.received_ns // box.servo.period_ns for a in got)
