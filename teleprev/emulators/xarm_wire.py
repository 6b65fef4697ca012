"""The xArm control box's wire format, as UFactory's developer manual describes it (facts, our code).

Commands (TCP port 502) are Modbus-TCP-like frames, big-endian header:

    transaction id u16 | protocol id u16 (2, or 3 from firmware 1.8.6 on) | length u16 | register u8 | data

`length` counts the register byte and the data. The reply repeats the transaction id, protocol id and
register, then a state byte and the register's data: state bit 0x40 = an error is latched, 0x20 = a
warning, 0x10 = not ready to move, 0x08 = the command was invalid. Floats in the data are little-endian
float32.

Reports (TCP 30001 "normal" and 30002 "rich", 5 Hz; 30003 "real", 100 Hz) are pushed by the controller: a u32
big-endian byte count, then the arm's state (see `pack_report`, `pack_real_report`; the layouts xarm-python-sdk
parses in xarm/x3/base.py, _handle_report_data, and xarm/x3/report.py, _Report30003DataStructure).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

COMMAND_PORT = 502
REPORT_NORMAL_PORT = 30001
REPORT_RICH_PORT = 30002
REPORT_REAL_PORT = 30003
REPORT_PERIOD_S = 0.2  # the normal and rich reports run at 5 Hz
REAL_REPORT_PERIOD_S = 0.01  # the real-time report (30003) at 100 Hz (UFactory developer manual, report ports)
REAL_REPORT_SIZE = 87  # xarm XCONF.SocketConf.TCP_REPORT_REAL_BUF_SIZE (135 with a force-torque sensor)

HEADER = struct.Struct(">HHHB")  # transaction, protocol, length, register

# Registers (the manual's table; the ones the SDK uses for a servo-mode session)
GET_VERSION = 1
GET_ROBOT_SN = 2
MOTION_EN = 11
SET_STATE = 12
GET_STATE = 13
GET_CMDNUM = 14
GET_ERROR = 15
CLEAN_ERR = 16
CLEAN_WAR = 17
SET_MODE = 19
MOVE_LINE = 21
MOVE_JOINT = 23
MOVE_HOME = 25
MOVE_SERVOJ = 29
GET_TCP_POSE = 41
GET_JOINT_POS = 42  # with a count byte (get_joint_states): positions, velocities and efforts, 7 floats each
GET_TCP_POSE_AA = 91
SET_FEEDBACK_TYPE = 254

# Reply state bits
ERROR_BIT = 0x40
WARNING_BIT = 0x20
NOT_READY_BIT = 0x10
INVALID_BIT = 0x08

# Arm states (report and GET_STATE): 5 is "CONFIG_CHANGED, system configuration or mode changed, not ready for
# motion commands" (xarm_ros xarm_msgs/RobotMsg.msg); set_state takes 0 (motion), 3, 4 and 6, "deceleration
# stop" (xarm.wrapper.XArmAPI.set_state)
MOVING, READY, PAUSED, STOPPED, CONFIG_CHANGED = 1, 2, 3, 4, 5
DECELERATION_STOP = 6
POSITION_MODE, SERVO_MODE = 0, 1

# Controller error codes the emulator raises (the manual's "C" codes)
ESTOP = 1  # the Emergency Stop Button on the control box is pushed in
JOINT_LIMIT = 23  # a joint's angle exceeds its limit
SPEED_LIMIT = 24  # a joint's speed exceeds its limit
COLLISION = 31  # collision caused abnormal current
SERVO_TCP_SPEED = 60  # "Linear speed exceeded limit in servo_j mode" (xarm x_code ControllerError 60)

RICH_REPORT_SIZE = 288
NORMAL_REPORT_SIZE = 145


def floats(values, n: int) -> bytes:
    v = list(values)[:n]
    return struct.pack(f"<{n}f", *(v + [0.0] * (n - len(v))))


def split_frames(buf: bytes) -> tuple[list[bytes], bytes]:
    """The whole frames at the start of `buf`, and the bytes after them (a frame still arriving)."""
    frames = []
    while len(buf) >= 6:
        end = 6 + struct.unpack(">H", buf[4:6])[0]
        if len(buf) < end:
            break
        frames.append(buf[:end])
        buf = buf[end:]
    return frames, buf


def reply(transaction: int, protocol: int, register: int, state: int, data: bytes = b"") -> bytes:
    return HEADER.pack(transaction, protocol, len(data) + 2, register) + bytes([state]) + data


@dataclass
class ReportState:
    """What a report carries."""

    state: int
    mode: int
    angles: np.ndarray  # rad, 7 values (unused joints 0)
    pose: np.ndarray  # TCP x, y, z (mm), roll, pitch, yaw (rad)
    speeds: np.ndarray  # rad/s, 7 values
    motors_enabled: bool
    error: int
    warning: int
    axis: int
    robot_type: int
    version: str
    counter: int


def pack_report(r: ReportState, size: int = RICH_REPORT_SIZE) -> bytes:
    """The rich report (30002), or its first NORMAL_REPORT_SIZE bytes (the normal one, 30001)."""
    motors = 0xFF if r.motors_enabled else 0
    out = bytearray(struct.pack(">IBH", size, (r.state & 0x0F) | (r.mode << 4), 0))
    out += floats(r.angles, 7)
    out += floats(r.pose, 6)
    out += floats([], 7)  # estimated joint torques
    out += bytes([motors, motors, r.error & 0xFF, r.warning & 0xFF])  # brakes released, motors enabled
    out += floats([], 6) + floats([], 4)  # TCP offset, TCP payload
    out += bytes([3, 3])  # collision and teaching sensitivity (0..5)
    out += floats([0.0, 0.0, -1.0], 3)  # gravity direction
    if size > NORMAL_REPORT_SIZE:
        out += bytes([r.robot_type, r.axis, 0, 0, 0, 0])
        out += r.version.encode()[:30].ljust(30, b"\0")
        out += floats([1000.0, 1.0, 50000.0, 0.1, 1000.0], 5)  # TCP jerk, acceleration and speed range
        out += floats([20.0, 0.01, 20.0, 0.0001, np.pi], 5)  # joint jerk, acceleration and speed range
        out += floats([2.3, 2.7], 2)  # rotation jerk and acceleration
        out += bytes(16)  # servo and tool GPIO status codes
        out += bytes([30] * 7)  # joint temperatures, deg C
        out += floats([0.0, *list(r.speeds)[:7]], 8)  # TCP speed, joint speeds
        out += struct.pack(">I", r.counter & 0xFFFFFFFF)
    assert len(out) == size, len(out)
    return bytes(out)


def pack_real_report(r: ReportState) -> bytes:
    """The real-time report (30003): size, state and mode, command count, angles, TCP pose, joint torques."""
    out = struct.pack(">IBH", REAL_REPORT_SIZE, (r.state & 0x0F) | (r.mode << 4), 0)
    out += floats(r.angles, 7) + floats(r.pose, 6) + floats([], 7)
    assert len(out) == REAL_REPORT_SIZE, len(out)
    return out
