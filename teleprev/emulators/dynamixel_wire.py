"""Dynamixel Protocol 2.0 packets and the X-series control table, as the ROBOTIS e-Manual gives them (facts,
our code).

A packet: FF FF FD 00 | id | length u16 LE | instruction | parameters | CRC-16 u16 LE, where `length`
counts the instruction, the parameters and the CRC. Inside the instruction and parameters, every
FF FF FD is followed by a stuffed FD. A status packet's instruction is 0x55, followed by the error byte
(bit 7: a hardware error is set; bits 0-6: the packet's error number) and the data.
"""

from __future__ import annotations

import struct

HEADER = b"\xff\xff\xfd\x00"
BROADCAST = 0xFE

PING, READ, WRITE, REBOOT, STATUS, SYNC_READ, SYNC_WRITE = 0x01, 0x02, 0x03, 0x08, 0x55, 0x82, 0x83

# status error numbers
RESULT_FAIL, INSTRUCTION_ERROR, CRC_ERROR, DATA_RANGE_ERROR, DATA_LENGTH_ERROR, DATA_LIMIT_ERROR, ACCESS_ERROR = range(1, 8)
ALERT = 0x80

# Control table (XC330 / XM430 X-series): address, size
MODEL_NUMBER = (0, 2)
FIRMWARE_VERSION = (6, 1)
ID = (7, 1)
OPERATING_MODE = (11, 1)
CURRENT_LIMIT = (38, 2)
TORQUE_ENABLE = (64, 1)
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
EEPROM_END = 64  # addresses below are EEPROM: written only with the torque off
TABLE_SIZE = 256

XC330_T288 = 1220  # the model number the e-Manual gives the XC330-T288-T

# Hardware Error Status bits
INPUT_VOLTAGE = 0x01
OVERHEATING = 0x04
MOTOR_ENCODER = 0x08
ELECTRICAL_SHOCK = 0x10
OVERLOAD = 0x20
HARDWARE_ERRORS = {INPUT_VOLTAGE: "input voltage error", OVERHEATING: "overheating", MOTOR_ENCODER: "motor encoder error",
                   ELECTRICAL_SHOCK: "electrical shock", OVERLOAD: "overload"}


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
