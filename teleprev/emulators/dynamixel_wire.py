"""Dynamixel Protocol 2.0 packets and the XC330-M288-T control table, as the ROBOTIS e-Manual gives them (facts,
our code: e-Manual "DYNAMIXEL Protocol 2.0" and "XC330-M288-T", emanual.robotis.com/docs/en/dxl/x/xc330-m288/).

A packet: FF FF FD 00 | id | length u16 LE | instruction | parameters | CRC-16 u16 LE, where `length`
counts the instruction, the parameters and the CRC. Inside the instruction and parameters, every
FF FF FD is followed by a stuffed FD. A status packet's instruction is 0x55, followed by the error byte
(bit 7: a hardware error is set; bits 0-6: the packet's error number) and the data.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

HEADER = b"\xff\xff\xfd\x00"
BROADCAST = 0xFE

PING, READ, WRITE, REBOOT, STATUS, SYNC_READ, SYNC_WRITE = 0x01, 0x02, 0x03, 0x08, 0x55, 0x82, 0x83
FAST_SYNC_READ, BULK_READ, BULK_WRITE, FAST_BULK_READ = 0x8A, 0x92, 0x93, 0x9A  # dynamixel_sdk.robotis_def

# status error numbers
RESULT_FAIL, INSTRUCTION_ERROR, CRC_ERROR, DATA_RANGE_ERROR, DATA_LENGTH_ERROR, DATA_LIMIT_ERROR, ACCESS_ERROR = range(
    1, 8
)
ALERT = 0x80

# Control table of the XC330-M288-T (e-Manual): address, size
MODEL_NUMBER = (0, 2)
FIRMWARE_VERSION = (6, 1)
ID = (7, 1)
BAUD_RATE = (8, 1)
RETURN_DELAY_TIME = (9, 1)
OPERATING_MODE = (11, 1)
CURRENT_LIMIT = (38, 2)
TORQUE_ENABLE = (64, 1)
STATUS_RETURN_LEVEL = (68, 1)
HARDWARE_ERROR_STATUS = (70, 1)
POSITION_D_GAIN = (80, 2)
POSITION_I_GAIN = (82, 2)
POSITION_P_GAIN = (84, 2)
GOAL_CURRENT = (102, 2)
GOAL_POSITION = (116, 4)
PRESENT_CURRENT = (126, 2)
PRESENT_VELOCITY = (128, 4)
PRESENT_POSITION = (132, 4)
PRESENT_INPUT_VOLTAGE = (144, 2)
PRESENT_TEMPERATURE = (146, 1)
EEPROM_END = 64  # addresses below are EEPROM: written only with the torque off ("CAUTION", control table)
TABLE_SIZE = 256

XC330_M288 = 1240  # Model Number of the XC330-M288-T, the LEAP Hand's motor (e-Manual control table)

# Baud Rate (8) values (e-Manual, X-series "Baud Rate"); the LEAP Hand's motors are set to 4 Mbps (value 6)
BAUD_RATES = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000, 5: 3_000_000, 6: 4_000_000, 7: 4_500_000}
OPERATING_MODES = (0, 1, 3, 4, 5, 16)  # current, velocity, position, extended position, current-based position, PWM


@dataclass(frozen=True)
class Field:
    """One item of the control table: where it is, whether it can be written, its power-on value and range."""

    name: str
    address: int
    size: int
    writable: bool
    initial: int
    low: int = 0
    high: int = 0
    signed: bool = False


# The XC330-M288-T's control table as the e-Manual lists it (Initial Value, Range, Access); the items the
# emulator models. Power-on values of RAM come back on a reboot; the LEAP Hand's motors carry their ID and
# 4 Mbps in EEPROM (set once with DYNAMIXEL Wizard), which a reboot keeps.
FIELDS = (
    Field("Model Number", 0, 2, False, XC330_M288),
    Field("Firmware Version", 6, 1, False, 52),
    Field("ID", 7, 1, True, 1, 0, 252),
    Field("Baud Rate", 8, 1, True, 1, 0, 7),
    Field("Return Delay Time", 9, 1, True, 250, 0, 254),  # 2 us per unit: 500 us
    Field("Drive Mode", 10, 1, True, 0, 0, 5),
    Field("Operating Mode", 11, 1, True, 3, 0, 16),  # and only OPERATING_MODES within it
    Field("Homing Offset", 20, 4, True, 0, -1_044_479, 1_044_479, signed=True),
    Field("Moving Threshold", 24, 4, True, 10, 0, 1023),
    Field("Temperature Limit", 31, 1, True, 70, 0, 100),
    Field("Max Voltage Limit", 32, 2, True, 70, 31, 70),
    Field("Min Voltage Limit", 34, 2, True, 35, 31, 70),
    Field("PWM Limit", 36, 2, True, 885, 0, 885),
    Field("Current Limit", 38, 2, True, 2352, 0, 2352),
    Field("Velocity Limit", 44, 4, True, 350, 0, 2047),
    Field("Max Position Limit", 48, 4, True, 4095, 0, 4095),
    Field("Min Position Limit", 52, 4, True, 0, 0, 4095),
    Field("Startup Configuration", 60, 1, True, 0, 0, 3),
    Field("PWM Slope", 62, 1, True, 140, 1, 255),
    Field("Shutdown", 63, 1, True, 52, 0, 255),
    Field("Torque Enable", 64, 1, True, 0, 0, 1),
    Field("LED", 65, 1, True, 0, 0, 1),
    Field("Status Return Level", 68, 1, True, 2, 0, 2),
    Field("Registered Instruction", 69, 1, False, 0),
    Field("Hardware Error Status", 70, 1, False, 0),
    Field("Velocity I Gain", 76, 2, True, 1600, 0, 16383),
    Field("Velocity P Gain", 78, 2, True, 50, 0, 16383),
    Field("Position D Gain", 80, 2, True, 500, 0, 16383),
    Field("Position I Gain", 82, 2, True, 0, 0, 16383),
    Field("Position P Gain", 84, 2, True, 1100, 0, 16383),
    Field("Feedforward 2nd Gain", 88, 2, True, 0, 0, 16383),
    Field("Feedforward 1st Gain", 90, 2, True, 0, 0, 16383),
    Field("Bus Watchdog", 98, 1, True, 0, 0, 127),
    Field("Goal PWM", 100, 2, True, 0, -885, 885, signed=True),  # within +-PWM Limit(36)
    Field("Goal Current", 102, 2, True, 0, -2352, 2352, signed=True),  # within +-Current Limit(38)
    Field("Goal Velocity", 104, 4, True, 0, -2047, 2047, signed=True),  # within +-Velocity Limit(44)
    Field("Profile Acceleration", 108, 4, True, 0, 0, 32767),
    Field("Profile Velocity", 112, 4, True, 0, 0, 32767),
    Field("Goal Position", 116, 4, True, 0, 0, 4095, signed=True),  # within the Min/Max Position Limits (48, 52)
    Field("Realtime Tick", 120, 2, False, 0),
    Field("Moving", 122, 1, False, 0),
    Field("Moving Status", 123, 1, False, 0),
    Field("Present PWM", 124, 2, False, 0),
    Field("Present Current", 126, 2, False, 0),
    Field("Present Velocity", 128, 4, False, 0),
    Field("Present Position", 132, 4, False, 0),
    Field("Velocity Trajectory", 136, 4, False, 0),
    Field("Position Trajectory", 140, 4, False, 0),
    Field("Present Input Voltage", 144, 2, False, 50),
    Field("Present Temperature", 146, 1, False, 32),
)
FIELD_AT = {f.address: f for f in FIELDS}
# A write within these limits, but past the limit another item sets, is a Data Limit Error (e-Manual:
# Goal Current "-Current Limit(38) ~ Current Limit(38)", and so on): item -> the item that limits it.
LIMITED_BY = {102: 38, 100: 36, 104: 44}

# Hardware Error Status bits
INPUT_VOLTAGE = 0x01
OVERHEATING = 0x04
MOTOR_ENCODER = 0x08
ELECTRICAL_SHOCK = 0x10
OVERLOAD = 0x20
HARDWARE_ERRORS = {
    INPUT_VOLTAGE: "input voltage error",
    OVERHEATING: "overheating",
    MOTOR_ENCODER: "motor encoder error",
    ELECTRICAL_SHOCK: "electrical shock",
    OVERLOAD: "overload",
}


def crc16(data: bytes) -> int:
    """CRC-16 of the e-Manual (polynomial 0x8005, initial value 0, not reflected)."""
    crc = 0
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x8005) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def stuff(body: bytes) -> bytes:
    return body.replace(b"\xff\xff\xfd", b"\xff\xff\xfd\xfd")


def unstuff(body: bytes) -> bytes:
    return body.replace(b"\xff\xff\xfd\xfd", b"\xff\xff\xfd")


def packet(dxl_id: int, instruction: int, params: bytes = b"", corrupt: bool = False) -> bytes:
    body = stuff(bytes([instruction]) + params)
    head = HEADER + bytes([dxl_id]) + struct.pack("<H", len(body) + 2)
    crc = crc16(head + body) ^ (0x5A5A if corrupt else 0)
    return head + body + struct.pack("<H", crc)


def status(dxl_id: int, error: int, data: bytes = b"", corrupt: bool = False) -> bytes:
    return packet(dxl_id, STATUS, bytes([error]) + data, corrupt)


def fast_status(parts: list[tuple[int, int, bytes]], corrupt: bool = False) -> bytes:
    """The one status packet that answers a Fast Sync Read or Fast Bulk Read (e-Manual, Protocol 2.0, "Fast Sync
    Read"): ID 0xFE, then for each device its error, ID, data and a CRC of the packet up to there; the last
    device's CRC ends the packet. Not byte-stuffed (dynamixel_sdk reads it with fast_option, unstuffed)."""
    length = 1 + sum(4 + len(data) for _, _, data in parts)
    out = bytearray(HEADER + bytes([BROADCAST]) + struct.pack("<H", length) + bytes([STATUS]))
    for error, dxl_id, data in parts:
        out += bytes([error, dxl_id]) + data
        out += struct.pack("<H", crc16(bytes(out)) ^ (0x5A5A if corrupt else 0))
    return bytes(out)


def hardware_errors(bits: int) -> str:
    return ", ".join(name for bit, name in HARDWARE_ERRORS.items() if bits & bit) or f"status 0x{bits:02x}"


class PacketReader:
    """Instruction packets out of a byte stream: (id, instruction, params), or (id, None, b"") for one
    whose CRC is wrong (a device answers that with a CRC error)."""

    def __init__(self):
        self.buf = b""

    def feed(self, data: bytes) -> list[tuple[int, int | None, bytes]]:
        self.buf += data
        out = []
        while True:
            start = self.buf.find(HEADER)
            if start < 0:
                self.buf = self.buf[-3:]
                return out
            self.buf = self.buf[start:]
            if len(self.buf) < 7:
                return out
            length = struct.unpack("<H", self.buf[5:7])[0]
            if len(self.buf) < 7 + length:
                return out
            frame, self.buf = self.buf[:7 + length], self.buf[7 + length:]
            if length < 3:
                continue
            crc = struct.unpack("<H", frame[-2:])[0]
            if crc16(frame[:-2]) != crc:
                out.append((frame[4], None, b""))
                continue
            body = unstuff(frame[7:-2])
            out.append((frame[4], body[0], body[1:]))
