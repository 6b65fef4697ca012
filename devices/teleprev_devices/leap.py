"""leap.hand: the 16-motor LEAP Hand over a Dynamixel bus (protocol 2.0) through dynamixel-sdk
(`uv sync --extra leap`).

    [devices.hand]
    plugin = "leap.hand"
    port = "/dev/ttyUSB0"
    current_limit_ma = 350     # 350 for the Lite hand, 550 for the Full one
    rate_hz = 90.0             # position reads; the bus manages about 90 Hz for positions alone

Joints "0".."15" are motors 0..15. The hand's "sim" angles (zero = flat open hand, as in the URDF) and
the motors' positions differ by pi: position = angle + pi, 4096 ticks per turn (2048 = open). Motors run
current-based position control (operating mode 5) with kP / kD (x0.75 on the side-to-side joints 0, 4
and 8) and a current limit, as the LEAP Hand's own driver sets them. The plugin talks to the bus
through DynamixelBus, a five-call interface; SdkDynamixelBus is the real one.

The bus's timing is the hardware's: a U2D2 (FTDI) adapter holds short replies for its latency timer (16 ms
by default), so on connect the plugin sets it to 1 ms through sysfs
(/sys/bus/usb-serial/devices/ttyUSBn/latency_timer) where it may, and says the exact command where it may
not (`teleprev devices check` shows which); `set_latency_timer = false` leaves it as it is (a lab that
keeps the adapter's setting, or measures the default). The motors' Return Delay Time is set to 0 (500 us each at
power-on: 8 ms per 16-motor read). While waiting for a reply the SDK's read loop sleeps in select() on the
port instead of spinning (dynamixel-sdk polls a non-blocking port until its packet timeout), so the rest
of the process runs.

One read that gets no (or a garbled, or an earlier request's late) reply is a counted miss ("read_misses",
ReadMiss), tried again at once, a command waiting for the bus going first; the hand faults when miss_limit
reads in a row fail. The plugin waits for a reply as long as the SDK does with the adapter's own timer (the
bytes, 2 x latency timer + 2 ms) plus HOST_DELAY_MS for the host's tty layer (see there): 100 ms with the
timer at 1 ms, 130 ms at 16 ms. So a hand that stops answering stops its commands within miss_limit x that
wait (5 x 100 ms = 0.5 s at 1 ms, 0.65 s at 16 ms), plus a poll period. A
register write on connect whose status packet does not come is sent again (WRITE_TRIES in all): writes are
idempotent, and one lost reply is no reason to refuse the hand.

A fault stops the hand's commands and says which motor and what: a Hardware Error Status bit
(overload, overheating, input voltage: the motor turned its torque off; checked every
hardware_check_every-th poll and before the torque comes on), a motor that does not answer, a corrupted
reply, the adapter unplugged. The session keeps recording; the runner reconnects once the hand answers
again. `teleprev devices emulate leap` runs an emulated bus to try a rig against.
"""

from __future__ import annotations

import math
import os
import select
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from teleprev.devices import DeviceContext, DeviceError, PolledActuator

try:  # pyserial flushing a port whose adapter is gone raises termios.error, which is no OSError
    from termios import error as _TermiosError

    PORT_ERRORS: tuple[type[BaseException], ...] = (OSError, _TermiosError)
except ImportError:  # Windows
    PORT_ERRORS = (OSError,)

# Control table (protocol 2.0, XC330/XM430 series): address, size in bytes.
RETURN_DELAY_TIME = (9, 1)
OPERATING_MODE = (11, 1)
TORQUE_ENABLE = (64, 1)
POSITION_D_GAIN = (80, 2)
POSITION_I_GAIN = (82, 2)
POSITION_P_GAIN = (84, 2)
HARDWARE_ERROR_STATUS = (70, 1)
GOAL_CURRENT = (102, 2)
GOAL_POSITION = (116, 4)
PRESENT_POSITION = (132, 4)

CURRENT_BASED_POSITION = 5
TICKS_PER_TURN = 4096
MOTOR_IDS = tuple(range(16))
SIDE_TO_SIDE = (0, 4, 8)
BAUDRATE = 4_000_000
HARDWARE_ERRORS = {0x01: "input voltage error", 0x04: "overheating", 0x08: "motor encoder error",
                   0x10: "electrical shock", 0x20: "overload"}  # Hardware Error Status bits (e-Manual)
ALERT = 0x80  # bit 7 of a status packet's error byte: the motor has a hardware error
USB_SERIAL_SYSFS = Path("/sys/bus/usb-serial/devices")  # where Linux's ftdi_sio exposes each port's latency_timer
LATENCY_TIMER_MS = 1  # the shortest the FTDI chip allows (AN232B-04: 1 to 255 ms)
WRITE_TRIES = 3  # a connect-time register write whose status packet is lost is sent again (writes are idempotent)
# How much longer than the bus itself takes a reply may reach the process. The adapter's driver (ftdi_sio)
# hands received bytes to the serial port through the kernel's tty flip buffer, pushed by a kernel worker
# scheduled like any ordinary process: on a loaded 2-core host that push waited up to 44 ms (p99 17 ms,
# bench/hardware.py's load plus other work), past the SDK's fixed 34.6 ms wait (its PortHandler assumes a
# 16 ms latency timer), so replies the motors sent in 2 ms were counted as misses and asked again.
HOST_DELAY_MS = 96.0


def ticks_from_angles(q: np.ndarray) -> np.ndarray:
    """Sim angles (rad) -> Dynamixel positions: (q + pi), 4096 per turn."""
    return np.rint((np.asarray(q, dtype=float) + math.pi) * (TICKS_PER_TURN / (2 * math.pi))).astype(np.int64)


def angles_from_ticks(ticks: np.ndarray) -> np.ndarray:
    return np.asarray(ticks, dtype=float) * (2 * math.pi / TICKS_PER_TURN) - math.pi


def hardware_error(motor: int, bits: int) -> str:
    names = ", ".join(n for b, n in HARDWARE_ERRORS.items() if bits & b) or "an unknown bit"
    return (f"motor {motor}: hardware error: {names} (Hardware Error Status 0x{bits:02x}); the motor turned its "
            "torque off and the hand's commands stopped: find the cause, then power-cycle the hand")


def signed32(value: int) -> int:
    """A 4-byte register as read (unsigned) to its signed value."""
    return value - (1 << 32) if value & 0x80000000 else value


class DynamixelBus(Protocol):
    """The motors as the plugin needs them. Every call raises DeviceError on failure; values are the
    registers' raw unsigned integers."""

    def open(self) -> None: ...
    def write(
        self, ids: Sequence[int], address: int, size: int, values: Sequence[int]
    ) -> None: ...  # each motor answers
    def sync_read(self, ids: Sequence[int], address: int, size: int) -> dict[int, int]: ...
    def sync_write(self, ids: Sequence[int], address: int, size: int, values: Sequence[int]) -> None: ...
    def close(self) -> None: ...


class PortGone(DeviceError):
    """The serial port itself failed (the adapter unplugged): no reply is coming, however long one waits."""


class ReadMiss(DeviceError):
    """A read without a good reply from every motor (none in time, a garbled one, or one meant for an earlier
    request): the bus's ordinary noise, counted and tried again (LeapHand._sync_read)."""


def latency_timer_path(port: str) -> Path:
    """The sysfs attribute holding the latency timer of the USB-serial adapter behind `port` (a by-id link
    resolves to its ttyUSBn)."""
    return USB_SERIAL_SYSFS / Path(os.path.realpath(port)).name / "latency_timer"


def set_latency_timer(path: Path, write: bool = True) -> tuple[int | None, str]:
    """Set the adapter's latency timer to LATENCY_TIMER_MS where allowed (only read it with write=False): (its
    value now, one line saying so)."""
    try:
        ms = int(path.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None, (f"no latency timer at {path} (not an FTDI adapter on Linux): replies come as the adapter "
                      "passes them on")
    if ms > LATENCY_TIMER_MS and write:
        try:
            path.write_text(f"{LATENCY_TIMER_MS}\n")
            ms = int(path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            pass
    if ms > LATENCY_TIMER_MS:
        why = "no permission to write it from here" if write else "left as it is: set_latency_timer = false"
        return ms, (f"USB adapter latency timer {ms} ms: every reply waits up to {ms} ms more; set it to 1 with "
                    f"`echo {LATENCY_TIMER_MS} | sudo tee {path}` ({why})")
    return ms, f"USB adapter latency timer {ms} ms ({path})"


def _wait_for_replies(port, latency_timer_ms: int | None) -> None:
    """Make the SDK wait for a reply as long as the bus and the host can take: its own wait (PortHandler.
    setPacketTimeout: the packet's bytes at the baud rate, 2 x the latency timer, 2 ms) with the adapter's own
    timer (16 ms where unknown: the SDK's constant), plus HOST_DELAY_MS."""
    timer_ms = 16 if latency_timer_ms is None else latency_timer_ms

    def set_packet_timeout(packet_length):
        port.packet_start_time = port.getCurrentTime()
        port.packet_timeout = reply_wait_ms(port.tx_time_per_byte * packet_length, timer_ms)

    port.setPacketTimeout = set_packet_timeout


def reply_wait_ms(bytes_ms: float, latency_timer_ms: int) -> float:
    """How long the plugin waits for a reply whose bytes take `bytes_ms` on the line."""
    return bytes_ms + 2.0 * latency_timer_ms + 2.0 + HOST_DELAY_MS


def _sleep_until_bytes(port) -> None:
    """Make the SDK's read loop sleep in select() until bytes arrive or its packet timeout ends, instead of
    polling the non-blocking port in a busy loop (dynamixel_sdk rxPacket), which starves the process."""
    ser, read = port.ser, port.readPort

    def read_port(length):
        if not ser.in_waiting:
            remaining_s = (port.packet_timeout - port.getTimeSinceStart()) / 1000.0
            if remaining_s > 0:
                select.select([ser.fileno()], [], [], remaining_s)
        return read(length)

    port.readPort = read_port


class SdkDynamixelBus:
    """DynamixelBus over dynamixel_sdk (PortHandler, PacketHandler 2.0, GroupSyncRead/Write)."""

    def __init__(self, port: str, baudrate: int = BAUDRATE, sdk=None, latency_timer: str = "",
                 set_timer: bool = True):
        self.port_name = port
        self.baudrate = baudrate
        self.latency_timer = Path(latency_timer) if latency_timer else latency_timer_path(port)
        self.set_timer = set_timer
        self.latency_timer_ms: int | None = None
        self.latency_note = ""
        self.where = f"Dynamixel bus {port}"
        self._sdk = sdk
        self.port = None

    def _gone(self, exc: Exception) -> DeviceError:
        return PortGone(f"the serial port stopped working (adapter unplugged?): {exc}", self.where)

    def open(self) -> None:
        sdk = self._sdk or LeapHand.import_sdk()
        self._sdk = sdk
        self.latency_timer_ms, self.latency_note = set_latency_timer(self.latency_timer, self.set_timer)
        self.port = sdk.PortHandler(self.port_name)
        self.packet = sdk.PacketHandler(2.0)
        try:
            opened = self.port.openPort() and self.port.setBaudRate(self.baudrate)
        except Exception as exc:  # pyserial raises when the device node is missing or busy
            self.port = None
            raise DeviceError(f"cannot open the serial port ({exc})", self.where) from None
        if not opened:
            raise DeviceError(f"cannot open the serial port at {self.baudrate} baud", self.where)
        _sleep_until_bytes(self.port)
        _wait_for_replies(self.port, self.latency_timer_ms)

    def _no_answer(self, result: int, motor: int | None, what: str, kind: type[DeviceError] = DeviceError
                   ) -> DeviceError:
        who = f"motor {motor}" if motor is not None else "a motor"
        if result == self._sdk.COMM_RX_TIMEOUT:
            said = f"{who} did not answer {what} (no status packet in time: unpowered, its cable, or another ID)"
        elif result == self._sdk.COMM_RX_CORRUPT:
            said = f"{who} sent a corrupted reply to {what} (bad CRC: noise, a loose cable, or the wrong baud rate)"
        else:
            said = f"{who}: {what}: {self.packet.getTxRxResult(result)}"
        return kind(said, self.where)

    def write(self, ids, address, size, values) -> None:
        """Write one register of each motor, each confirmed by its status packet. A reply that does not come
        (or comes garbled) is the line's noise: the same value is written again, WRITE_TRIES times in all,
        since writing it twice leaves the motor as writing it once."""
        call = {1: self.packet.write1ByteTxRx, 2: self.packet.write2ByteTxRx, 4: self.packet.write4ByteTxRx}[size]
        for i, v in zip(ids, values):
            what = f"writing {int(v)} at address {address}"
            for _ in range(WRITE_TRIES):
                try:
                    result, error = call(self.port, i, address, int(v))
                except PORT_ERRORS as exc:
                    raise self._gone(exc) from None
                if result not in (self._sdk.COMM_RX_TIMEOUT, self._sdk.COMM_RX_CORRUPT):
                    break
            if result != self._sdk.COMM_SUCCESS:
                raise self._no_answer(result, i, what + (f" ({WRITE_TRIES} tries)" if result in (
                    self._sdk.COMM_RX_TIMEOUT, self._sdk.COMM_RX_CORRUPT) else ""))
            if error & ALERT:
                bits, _, _ = self.packet.read1ByteTxRx(self.port, i, HARDWARE_ERROR_STATUS[0])
                raise DeviceError(hardware_error(i, bits), self.where)
            if error:
                raise DeviceError(f"motor {i}: {what}: {self.packet.getRxPacketError(error)}", self.where)

    def sync_read(self, ids, address, size) -> dict[int, int]:
        group = self._sdk.GroupSyncRead(self.port, self.packet, address, size)
        for i in ids:
            group.addParam(i)
        what = f"the sync read at address {address}"
        try:
            result = group.txRxPacket()
        except PORT_ERRORS as exc:
            raise self._gone(exc) from None
        except (IndexError, ValueError) as exc:  # the SDK parsing bytes that are no whole packet
            raise ReadMiss(f"a garbled reply to {what} ({type(exc).__name__}: {exc})", self.where) from None
        if result != self._sdk.COMM_SUCCESS:
            # the group reads the motors in turn and stops at the first that fails: the first without data
            failed = next((i for i in ids if not group.data_dict.get(i)), None)
            raise self._no_answer(result, failed, what, ReadMiss)
        missing = [i for i in ids if not group.isAvailable(i, address, size)]
        if missing:
            raise ReadMiss(f"motors {missing} did not answer {what}", self.where)
        # a status packet from the right motor but for an earlier request (it came after the SDK stopped
        # waiting for it) carries another read's bytes; the SDK takes it as this read's answer
        short = [i for i in ids if len(group.data_dict[i]) != size]
        if short:
            raise ReadMiss(f"motor {short[0]} answered {what} with {len(group.data_dict[short[0]])} bytes, not "
                           f"{size} (a late reply to an earlier request)", self.where)
        return {i: group.getData(i, address, size) for i in ids}

    def sync_write(self, ids, address, size, values) -> None:
        group = self._sdk.GroupSyncWrite(self.port, self.packet, address, size)
        for i, v in zip(ids, values):
            group.addParam(i, list(int(v).to_bytes(size, "little", signed=False)))
        try:
            result = group.txPacket()
        except PORT_ERRORS as exc:
            raise self._gone(exc) from None
        if result != self._sdk.COMM_SUCCESS:
            raise DeviceError(f"sync write at address {address}: {self.packet.getTxRxResult(result)}", self.where)

    def close(self) -> None:
        port, self.port = self.port, None
        if port is not None and getattr(port, "is_open", True):
            try:
                port.closePort()
            except PORT_ERRORS:
                pass  # the adapter is already gone


@dataclass
class LeapSettings:
    port: str = "/dev/ttyUSB0"  # the U2D2's serial device (COM3 on Windows)
    rate_hz: float = 90.0
    kp: int = 600
    kd: int = 200
    current_limit_ma: int = 350  # Lite 350, Full 550 (XC330 goal current is in mA)
    hardware_check_every: int = 9  # polls between reads of the motors' Hardware Error Status (10 Hz at 90 Hz)
    miss_limit: int = 5  # reads in a row without a (good) reply before the hand faults; fewer are counted misses
    # The adapter's latency timer; default: found from `port` in /sys/bus/usb-serial/devices.
    latency_timer_path: str = ""
    set_latency_timer: bool = True  # false: leave the timer as it is (reads then wait for it; see the docstring)

    def __post_init__(self):
        if not self.port:
            raise ValueError("port is required, e.g. port = \"/dev/ttyUSB0\"")
        if not 0 < self.rate_hz <= 90:
            raise ValueError(f"rate_hz must be in (0, 90] (position reads manage about 90 Hz), got {self.rate_hz}")
        if not (0 <= self.kp <= 16383 and 0 <= self.kd <= 16383):
            raise ValueError(f"kp and kd must be 0..16383, got {self.kp} and {self.kd}")
        if not 0 < self.current_limit_ma <= 1000:
            raise ValueError(f"current_limit_ma must be 1..1000, got {self.current_limit_ma}")
        if not 1 <= self.hardware_check_every <= 1000:
            raise ValueError(f"hardware_check_every must be 1..1000, got {self.hardware_check_every}")
        if not 1 <= self.miss_limit <= 100:
            raise ValueError(f"miss_limit must be 1..100, got {self.miss_limit}")


class LeapHand(PolledActuator[LeapSettings], kind="hand", sdk_module="dynamixel_sdk", extra="leap"):
    """JointSample of "0".."15" on /hand/<name>/state; send() writes goal positions."""

    own_process = True  # the bus's reads and writes both run in a paced process of their own (Actuator)

    def __init__(self, name: str, settings: LeapSettings, context: DeviceContext, bus: DynamixelBus | None = None):
        robot = context.robot if _has_joint(context.robot, "0") else "leap_hand_right"  # the hand alone otherwise
        super().__init__(name, settings, context, robot, tuple(str(i) for i in MOTOR_IDS),
                         where=f"device {name!r} (LEAP Hand on {settings.port})")
        self.bus: DynamixelBus = bus or SdkDynamixelBus(settings.port, latency_timer=settings.latency_timer_path,
                                                              set_timer=settings.set_latency_timer)
        self._polls = 0
        self._misses = 0

    def endpoint(self) -> str:
        return f"serial {self.settings.port}"

    def _open(self) -> None:
        self.bus.open()

    def _start(self) -> np.ndarray:
        s = self.settings
        ids = list(MOTOR_IDS)

        def gains(g: int) -> list[int]:
            return [round(0.75 * g) if i in SIDE_TO_SIDE else g for i in ids]

        self.bus.write(ids, *TORQUE_ENABLE, [0] * 16)  # the operating mode only changes with torque off
        self._check_hardware()
        delays = self._sync_read(RETURN_DELAY_TIME)
        if any(delays.values()):  # EEPROM: written once, not at every connect
            self.bus.write(ids, *RETURN_DELAY_TIME, [0] * 16)
        self.bus.write(ids, *OPERATING_MODE, [CURRENT_BASED_POSITION] * 16)
        self.bus.write(ids, *POSITION_P_GAIN, gains(s.kp))
        self.bus.write(ids, *POSITION_I_GAIN, [0] * 16)
        self.bus.write(ids, *POSITION_D_GAIN, gains(s.kd))
        self.bus.write(ids, *GOAL_CURRENT, [s.current_limit_ma] * 16)
        q = self._poll()
        # Hold where the hand is before torque comes on, so it does not jump to a stale goal.
        self.bus.sync_write(ids, *GOAL_POSITION, ticks_from_angles(q).tolist())
        self.bus.write(ids, *TORQUE_ENABLE, [1] * 16)
        return q

    def _close(self) -> None:
        self.bus.close()

    def counters(self) -> dict[str, int]:
        return {**super().counters(), "read_misses": self._misses}

    def notes(self) -> list[str]:
        """What `teleprev devices check` prints about the hand's bus: its adapter's latency timer."""
        note = getattr(self.bus, "latency_note", "")
        return [note] if note else []

    def _sync_read(self, field: tuple[int, int]) -> dict[int, int]:
        """A sync read, tried until it succeeds or miss_limit tries in a row have failed: a reply lost, late or
        garbled is the bus's ordinary noise (a counted miss); miss_limit in a row is a hand that stopped.
        Between two tries a command waiting for the bus goes first (the hand's writes do not wait out a
        read's retries)."""
        failures: list[ReadMiss] = []
        while len(failures) < self.settings.miss_limit:
            if failures and self._connected:
                self._let_commands_through()
            try:
                return self.bus.sync_read(list(MOTOR_IDS), *field)
            except ReadMiss as exc:
                failures.append(exc)
                self._misses += 1
        raise failures[0]  # what went wrong first (later tries on a dead bus say less)

    def _check_hardware(self) -> None:
        status = self._sync_read(HARDWARE_ERROR_STATUS)
        bad = [i for i in MOTOR_IDS if status[i]]
        if bad:
            raise DeviceError(hardware_error(bad[0], status[bad[0]]) + (f" (also motors {bad[1:]})" if bad[1:] else ""),
                              self.where)

    def _poll(self) -> np.ndarray:
        self._polls += 1
        if self._polls % self.settings.hardware_check_every == 0:
            self._check_hardware()
        raw = self._sync_read(PRESENT_POSITION)
        return angles_from_ticks(np.array([signed32(raw[i]) for i in MOTOR_IDS]))

    def _write(self, target: np.ndarray) -> None:
        self.bus.sync_write(list(MOTOR_IDS), *GOAL_POSITION, ticks_from_angles(target).tolist())


def _has_joint(robot: str, joint: str) -> bool:
    from teleprev.devices import load_robot

    try:
        return joint in load_robot(robot).joint_index
    except Exception:
        return False
