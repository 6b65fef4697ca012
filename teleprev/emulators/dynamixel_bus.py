"""An emulated Dynamixel Protocol 2.0 bus with the LEAP Hand's 16 motors, on a pseudo-terminal that pyserial
and dynamixel-sdk open like a U2D2 USB adapter.

    with DynamixelBus().start() as bus:          # bus.port: a stable path, like /dev/serial/by-id/...
        ...                                      # leap.hand with port = bus.port
        bus.inject("overload", motor=5)          # motor 5 sets its Hardware Error Status, torque off
        bus.operator_clear()                     # power-cycled: errors gone, every motor answers

The motors (IDs 0..15, X-series control table) answer PING, READ, WRITE, SYNC_READ, SYNC_WRITE and
REBOOT as the e-Manual describes: EEPROM (addresses below 64) is written only with the torque off; a
motor with a hardware error sets bit 7 of every status packet's error byte and keeps its torque off;
with the torque on, a motor moves from where it is towards its goal position at its no-load speed.

Injected faults (`inject(kind, motor)`): overload, overheating, input_voltage (Hardware Error Status
bits), silent (the motor stops answering), bad_crc (every reply's CRC is wrong until cleared), unplug
(the pseudo-terminal closes and the port's path disappears, as when the adapter is pulled out; `plug()`
puts it back at the same path).
"""

from __future__ import annotations

import os
import select
import struct
import tempfile
import threading
import time
import tty
from collections import Counter
from pathlib import Path

from teleprev.emulators import dynamixel_wire as wire
from teleprev.emulators.listening import EmulatorError

FAULTS = ("overload", "overheating", "input_voltage", "silent", "bad_crc", "unplug")
HARDWARE_FAULTS = {"overload": wire.OVERLOAD, "overheating": wire.OVERHEATING, "input_voltage": wire.INPUT_VOLTAGE}
MOTOR_IDS = tuple(range(16))
OPEN_HAND = 2048  # ticks: the LEAP Hand's flat open hand
REPLY_MARGIN_MS = 150.0  # the rig keys' reply_margin_ms: the emulator shares the host's cores with the session
NO_LOAD_SPEED = 65 * 4096 / 60  # ticks/s: about 65 rev/min at the output


class Motor:
    def __init__(self, dxl_id: int, position: int = OPEN_HAND):
        self.id = dxl_id
        self.table = bytearray(wire.TABLE_SIZE)
        self.set(wire.MODEL_NUMBER, wire.XC330_T288)
        self.set(wire.FIRMWARE_VERSION, 52)
        self.set(wire.ID, dxl_id)
        self.set(wire.OPERATING_MODE, 3)
        self.set(wire.CURRENT_LIMIT, 910)
        self.set(wire.PRESENT_INPUT_VOLTAGE, 50)
        self.set(wire.PRESENT_TEMPERATURE, 32)
        self.set(wire.PRESENT_POSITION, position)
        self.set(wire.GOAL_POSITION, position)
        self.position = float(position)
        self.silent = False
        self._moved = time.monotonic()

    def get(self, field: tuple[int, int]) -> int:
        address, size = field
        return int.from_bytes(self.table[address:address + size], "little")

    def set(self, field: tuple[int, int], value: int) -> None:
        address, size = field
        self.table[address:address + size] = (int(value) & ((1 << 8 * size) - 1)).to_bytes(size, "little")

    @property
    def hardware_error(self) -> int:
        return self.get(wire.HARDWARE_ERROR_STATUS)

    def step(self, now: float) -> None:
        """Move towards the goal (torque on) at the no-load speed; update present position and velocity."""
        dt, self._moved = now - self._moved, now
        velocity = 0.0
        if self.get(wire.TORQUE_ENABLE):
            goal = self.get(wire.GOAL_POSITION)
            goal = goal - (1 << 32) if goal & 0x80000000 else goal
            reach = NO_LOAD_SPEED * dt
            delta = max(-reach, min(reach, goal - self.position))
            self.position += delta
            velocity = delta / dt if dt > 0 else 0.0
        self.set(wire.PRESENT_POSITION, round(self.position))
        self.set(wire.PRESENT_VELOCITY, round(velocity / 4096 * 60 / 0.229))  # 0.229 rev/min per unit
        self.set(wire.PRESENT_CURRENT, 12 if self.get(wire.TORQUE_ENABLE) else 0)  # mA

    def write(self, address: int, data: bytes) -> int:
        """The status error for a write (0: done)."""
        if address + len(data) > wire.TABLE_SIZE:
            return wire.DATA_RANGE_ERROR
        if address < wire.EEPROM_END and self.get(wire.TORQUE_ENABLE):
            return wire.ACCESS_ERROR
        if address == wire.TORQUE_ENABLE[0] and self.hardware_error:
            data = b"\x00" + data[1:]  # no torque until the error is gone
        if address <= wire.GOAL_POSITION[0] < address + len(data) and self.get(wire.TORQUE_ENABLE):
            self.step(time.monotonic())
        self.table[address:address + len(data)] = data
        if address == wire.TORQUE_ENABLE[0]:
            self._moved = time.monotonic()
        return 0


class DynamixelBus:
    def __init__(self, port: str | Path | None = None, positions: dict[int, int] | None = None):
        self._dir = None
        if port is None:
            self._dir = tempfile.mkdtemp(prefix="teleprev-dxl-")
            port = Path(self._dir) / "ttyLEAP"
        self.port = str(port)
        self.motors = {i: Motor(i, (positions or {}).get(i, OPEN_HAND)) for i in MOTOR_IDS}
        self._lock = threading.Lock()
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bad_crc = False
        self.requests: Counter[int] = Counter()
        self.goal_writes = 0  # sync writes of the goal position
        self.corrupt_requests = 0
        self.injected: list[tuple[int, str, int]] = []

    # ---- lifecycle -----------------------------------------------------------------------------------
    def start(self) -> DynamixelBus:
        self.plug()
        return self

    def plug(self) -> None:
        """The adapter plugged in: a new pseudo-terminal, reachable at `port`."""
        try:
            master, slave = os.openpty()
        except OSError as exc:
            raise EmulatorError(f"cannot open a pseudo-terminal for the Dynamixel bus: {exc.strerror}") from None
        tty.setraw(slave)  # bytes pass unchanged: no echo, no line discipline
        link = Path(self.port)
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(os.ttyname(slave))
        with self._lock:
            self._master, self._slave = master, slave
        self._stop.clear()
        self._thread = threading.Thread(target=self._serve, args=(master,), name="emulator-dynamixel", daemon=True)
        self._thread.start()

    def unplug(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
        with self._lock:
            fds, self._master, self._slave = (self._master, self._slave), -1, -1
        for fd in fds:
            if fd >= 0:
                os.close(fd)
        link = Path(self.port)
        if link.is_symlink():
            link.unlink()

    @property
    def plugged(self) -> bool:
        return self._master >= 0

    def stop(self) -> None:
        self.unplug()
        if self._dir:
            try:
                os.rmdir(self._dir)
            except OSError:
                pass

    def __enter__(self) -> DynamixelBus:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def rig_keys(self, name: str = "hand") -> str:
        # The bus answers from a thread on this host's cores: the margin keeps a busy host from reading as
        # a silent motor (a real bus needs none).
        return f'[devices.{name}]\nplugin = "leap.hand"\nport = "{self.port}"\nreply_margin_ms = {REPLY_MARGIN_MS:g}\n'

    # ---- faults ---------------------------------------------------------------------------------------
    def inject(self, kind: str, motor: int = 0) -> None:
        if kind not in FAULTS:
            raise ValueError(f"unknown fault {kind!r} (one of {', '.join(FAULTS)})")
        self.injected.append((time.monotonic_ns(), kind, motor))
        if kind == "unplug":
            self.unplug()
            return
        with self._lock:
            m = self.motors[motor]
            if kind in HARDWARE_FAULTS:
                m.set(wire.HARDWARE_ERROR_STATUS, m.hardware_error | HARDWARE_FAULTS[kind])
                m.step(time.monotonic())
                m.set(wire.TORQUE_ENABLE, 0)
            elif kind == "silent":
                m.silent = True
            elif kind == "bad_crc":
                self.bad_crc = True

    def operator_clear(self) -> None:
        """The hand power-cycled and the adapter back in: no hardware errors, every motor answers."""
        with self._lock:
            self.bad_crc = False
            for m in self.motors.values():
                m.silent = False
                m.set(wire.HARDWARE_ERROR_STATUS, 0)
        if not self.plugged:
            self.plug()

    def positions(self) -> dict[int, int]:
        with self._lock:
            now = time.monotonic()
            for m in self.motors.values():
                m.step(now)
            return {i: m.get(wire.PRESENT_POSITION) for i, m in self.motors.items()}

    # ---- the bus ---------------------------------------------------------------------------------------
    def _serve(self, master: int) -> None:
        # Real motors answer within microseconds whatever the host does, and dynamixel-sdk waits only 34 ms:
        # where allowed (root), this thread answers before the host's other work (it mostly sleeps in select).
        try:
            os.sched_setscheduler(threading.get_native_id(), os.SCHED_FIFO, os.sched_param(10))
        except (OSError, AttributeError):
            pass
        reader = wire.PacketReader()
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([master], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(master, 4096)
            except OSError:
                return
            out = b""
            for dxl_id, instruction, params in reader.feed(data):
                out += self._answer(dxl_id, instruction, params)
            if out:
                try:
                    os.write(master, out)
                except OSError:
                    return

    def _reply(self, m: Motor, error: int, data: bytes = b"") -> bytes:
        if m.silent:
            return b""
        return wire.status(m.id, error | (wire.ALERT if m.hardware_error else 0), data, corrupt=self.bad_crc)

    def _answer(self, dxl_id: int, instruction: int | None, params: bytes) -> bytes:
        with self._lock:
            if instruction is None:
                self.corrupt_requests += 1
                m = self.motors.get(dxl_id)
                return self._reply(m, wire.CRC_ERROR) if m else b""
            self.requests[instruction] += 1
            now = time.monotonic()
            if instruction == wire.SYNC_WRITE and len(params) >= 4:
                address, size = struct.unpack("<HH", params[:4])
                body = params[4:]
                for k in range(0, len(body) - size + 1, size + 1):
                    m = self.motors.get(body[k])
                    if m is not None and not m.silent:
                        m.write(address, body[k + 1:k + 1 + size])
                if address == wire.GOAL_POSITION[0]:
                    self.goal_writes += 1
                return b""
            if instruction == wire.SYNC_READ and len(params) >= 4:
                address, size = struct.unpack("<HH", params[:4])
                out = b""
                for i in params[4:]:
                    m = self.motors.get(i)
                    if m is not None:
                        m.step(now)
                        out += self._reply(m, 0, bytes(m.table[address:address + size]))
                return out
            m = self.motors.get(dxl_id)
            if m is None:
                return b""
            if instruction == wire.PING:
                return self._reply(m, 0, struct.pack("<HB", m.get(wire.MODEL_NUMBER), m.get(wire.FIRMWARE_VERSION)))
            if instruction == wire.READ and len(params) >= 4:
                address, size = struct.unpack("<HH", params[:4])
                m.step(now)
                return self._reply(m, 0, bytes(m.table[address:address + size]))
            if instruction == wire.WRITE and len(params) >= 2:
                address = struct.unpack("<H", params[:2])[0]
                return self._reply(m, m.write(address, params[2:]))
            if instruction == wire.REBOOT:
                m.set(wire.HARDWARE_ERROR_STATUS, 0)
                m.set(wire.TORQUE_ENABLE, 0)
                return self._reply(m, 0)
            return self._reply(m, wire.INSTRUCTION_ERROR)
