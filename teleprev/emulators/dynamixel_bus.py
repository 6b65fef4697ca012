"""An emulated Dynamixel Protocol 2.0 bus with the LEAP Hand's 16 XC330-M288-T motors behind a U2D2 (FTDI)
USB adapter, on a pseudo-terminal that pyserial and dynamixel-sdk open like the adapter's /dev/ttyUSBn.

    with DynamixelBus().start() as bus:          # bus.port: a stable path, like /dev/serial/by-id/...
        ...                                      # leap.hand with the rig keys bus.rig_keys() gives
        bus.inject("overload", motor=5)          # motor 5 sets its Hardware Error Status, torque off
        bus.operator_clear()                     # power-cycled: errors gone, every motor answers

Everything here is the e-Manual's (Protocol 2.0; the XC330-M288-T control table, see dynamixel_wire) or the
adapter's (FTDI AN232B-04), never what a plugin would like:
- the motors answer PING, READ, WRITE, REBOOT, SYNC_READ, SYNC_WRITE, FAST_SYNC_READ, BULK_READ, BULK_WRITE and
  FAST_BULK_READ; to the broadcast ID only PING and the group reads are answered ("Status Packet is not returned
  for broadcast", Protocol 2.0 "Instruction Packet"), and Status Return Level 0 / 1 leaves out all but PING /
  PING and reads;
- writes are checked as the control table says: read-only items (Access Error), EEPROM with the torque on
  (Access Error), outside an item's range (Data Range Error), past the limit another item sets, e.g. Goal
  Current above Current Limit (Data Limit Error), part of a multi-byte item (Data Length Error);
- power-on values per the control table, which a reboot brings back for the RAM area;
- timing: a motor answers Return Delay Time (2 us per unit, 500 us at power-on) after the bus went quiet,
  its bytes take 10 bits each at the baud rate, and the adapter hands bytes to the host in 62-byte USB
  packets, a short one only when its latency timer runs out (16 ms by default, "reset every time data is
  sent back to the PC": AN232B-04, "Small Amounts of Data and End of Buffer Conditions"). The timer is read
  from `latency_timer_path`, the file the Linux ftdi_sio driver exposes in sysfs; writing 1 there makes it 1 ms;
- a motor set to another baud rate than the port hears nothing it can decode, and says nothing.

Injected faults (`inject(kind, motor)`): overload, overheating, input_voltage (Hardware Error Status
bits), silent (the motor stops answering), bad_crc (every reply's CRC is wrong until cleared), unplug
(the pseudo-terminal closes and the port's path disappears, as when the adapter is pulled out; `plug()`
puts it back at the same path), lost_reply (the motor acts on its next request but its status packet is
lost on the line), stale_reply (before its next reply the motor's answer to an earlier 1-byte read reaches
the host: a reply that came after the host stopped waiting for it).
"""

from __future__ import annotations

import math
import os
import select
import shutil
import struct
import tempfile
import termios
import threading
import time
import tty
from collections import Counter
from pathlib import Path

from teleprev.emulators import dynamixel_wire as wire
from teleprev.emulators.listening import EmulatorError

FAULTS = ("overload", "overheating", "input_voltage", "silent", "bad_crc", "unplug", "lost_reply", "stale_reply")
HARDWARE_FAULTS = {"overload": wire.OVERLOAD, "overheating": wire.OVERHEATING, "input_voltage": wire.INPUT_VOLTAGE}
MOTOR_IDS = tuple(range(16))
OPEN_HAND = 2048  # ticks: the LEAP Hand's flat open hand
LEAP_BAUD = 6  # Baud Rate (8) = 4 Mbps: how the LEAP Hand's motors are set up (its driver opens the port at 4 Mbps)
NO_LOAD_SPEED = 81 * 4096 / 60  # ticks/s: 81 rev/min at 5.0 V (XC330-M288-T specifications)
FTDI_PACKET = 62  # user bytes in one 64-byte USB packet (AN232B-04: 2 status bytes and 62 user bytes)
FTDI_DEFAULT_LATENCY_MS = 16  # AN232B-04: "The default value of the timer is set to 16 milliseconds"
POSITION_RANGE = 1_048_575  # Goal Position in modes other than position control (e-Manual, Goal Position)
REPLY_PRIORITY = 10  # SCHED_FIFO priority of the thread that answers (where allowed): before ordinary processes
READS = (wire.READ, wire.SYNC_READ, wire.FAST_SYNC_READ, wire.BULK_READ, wire.FAST_BULK_READ)


class Motor:
    """One XC330-M288-T: its control table and where its horn is."""

    def __init__(self, dxl_id: int, position: int = OPEN_HAND, baud: int = LEAP_BAUD):
        self.table = bytearray(wire.TABLE_SIZE)
        for f in wire.FIELDS:
            self._store(f, f.initial)
        self.set(wire.ID, dxl_id)  # ID and baud rate: EEPROM, as the LEAP Hand's motors are configured
        self.set(wire.BAUD_RATE, baud)
        self.position = float(position)
        self.silent = False
        self.lose_next = False  # injected: the next status packet is lost
        self.stale_next = False  # injected: an earlier request's late reply goes before the next one
        self._moved = time.monotonic()
        self.reboot()

    @property
    def id(self) -> int:
        return self.get(wire.ID)

    def get(self, field: tuple[int, int]) -> int:
        address, size = field
        return int.from_bytes(self.table[address:address + size], "little")

    def set(self, field: tuple[int, int], value: int) -> None:
        address, size = field
        self.table[address:address + size] = (int(value) & ((1 << 8 * size) - 1)).to_bytes(size, "little")

    def _store(self, f: wire.Field, value: int) -> None:
        self.set((f.address, f.size), value)

    def _value(self, f: wire.Field) -> int:
        return int.from_bytes(self.table[f.address:f.address + f.size], "little", signed=f.signed)

    @property
    def hardware_error(self) -> int:
        return self.get(wire.HARDWARE_ERROR_STATUS)

    @property
    def return_delay_s(self) -> float:
        return self.get(wire.RETURN_DELAY_TIME) * 2e-6  # 2 [usec] per unit

    def reboot(self) -> None:
        """Power-on: the RAM area (64 and up) back to its initial values, EEPROM kept (e-Manual, Reboot)."""
        for f in wire.FIELDS:
            if f.address >= wire.EEPROM_END:
                self._store(f, f.initial)
        self.set(wire.GOAL_POSITION, round(self.position))
        self.step(time.monotonic())

    def step(self, now: float) -> None:
        """Move towards the goal (torque on) at the no-load speed; update present position and velocity."""
        dt, self._moved = now - self._moved, now
        velocity = 0.0
        if self.get(wire.TORQUE_ENABLE):
            goal = self._value(wire.FIELD_AT[wire.GOAL_POSITION[0]])
            reach = NO_LOAD_SPEED * dt
            delta = max(-reach, min(reach, goal - self.position))
            self.position += delta
            velocity = delta / dt if dt > 0 else 0.0
        self.set(wire.PRESENT_POSITION, round(self.position))
        self.set(wire.PRESENT_VELOCITY, round(velocity / 4096 * 60 / 0.229))  # 0.229 rev/min per unit
        self.set(wire.PRESENT_CURRENT, 12 if self.get(wire.TORQUE_ENABLE) else 0)  # mA

    def _limit_error(self, f: wire.Field, value: int, pending: dict[int, int]) -> bool:
        """Past the limit another item sets (the e-Manual's ranges written as "... Limit(38)")."""
        if f.address in wire.LIMITED_BY:
            limiter = wire.FIELD_AT[wire.LIMITED_BY[f.address]]
            limit = pending.get(limiter.address, self._value(limiter))
            return abs(value) > limit
        if f.address == wire.GOAL_POSITION[0]:
            if self.get(wire.OPERATING_MODE) == 3:  # position control: within the Min/Max Position Limits
                return not self.get((52, 4)) <= value <= self.get((48, 4))
            return abs(value) > POSITION_RANGE
        return False

    def write(self, address: int, data: bytes) -> int:
        """The status error for a write (0: done); nothing is written unless all of it is allowed."""
        end = address + len(data)
        if end > wire.TABLE_SIZE or not data:
            return wire.DATA_LENGTH_ERROR
        touched = [f for f in wire.FIELDS if f.address < end and address < f.address + f.size]
        for f in touched:
            if f.address < address or f.address + f.size > end:
                return wire.DATA_LENGTH_ERROR  # part of a multi-byte item
            if not f.writable or (f.address < wire.EEPROM_END and self.get(wire.TORQUE_ENABLE)):
                return wire.ACCESS_ERROR
        pending = {}
        for f in touched:
            raw = data[f.address - address:f.address - address + f.size]
            pending[f.address] = int.from_bytes(raw, "little", signed=f.signed)
        for f in touched:
            value = pending[f.address]
            if f.address == wire.GOAL_POSITION[0] or f.address in wire.LIMITED_BY:  # bounded by another item
                if self._limit_error(f, value, pending):
                    return wire.DATA_LIMIT_ERROR
                continue
            if not f.low <= value <= f.high or (
                f.address == wire.OPERATING_MODE[0] and value not in wire.OPERATING_MODES
            ):
                return wire.DATA_RANGE_ERROR
            if self._limit_error(f, value, pending):
                return wire.DATA_LIMIT_ERROR
        now = time.monotonic()
        if self.get(wire.TORQUE_ENABLE):
            self.step(now)
        for f in touched:
            value = pending[f.address]
            if f.address == wire.TORQUE_ENABLE[0] and self.hardware_error:
                value = 0  # no torque while a hardware error is set (e-Manual, Hardware Error Status)
            self._store(f, value)
        if wire.TORQUE_ENABLE[0] in pending:
            self._moved = now
        return 0

    def read(self, address: int, size: int) -> tuple[int, bytes]:
        if address + size > wire.TABLE_SIZE:
            return wire.DATA_RANGE_ERROR, b""
        self.step(time.monotonic())
        return 0, bytes(self.table[address:address + size])

    def answers(self, instruction: int) -> bool:
        """Status Return Level (68): 0 answers PING only, 1 PING and reads, 2 everything."""
        level = self.get(wire.STATUS_RETURN_LEVEL)
        return instruction == wire.PING or level == 2 or (level == 1 and instruction in READS)


class FtdiAdapter:
    """When bytes the motors sent reach the host: 62-byte USB packets go at once, a short one when the latency
    timer runs out; the timer restarts at every packet sent (AN232B-04), and the chip sends one at least every
    latency period, so an idle adapter's timer runs in steps of that period."""

    def __init__(self, latency_timer_path: Path):
        self.path = latency_timer_path
        self._last_sent = time.monotonic()

    @property
    def latency_s(self) -> float:
        try:
            ms = int(self.path.read_text().split()[0])
        except (OSError, ValueError, IndexError):
            ms = FTDI_DEFAULT_LATENCY_MS
        return min(max(ms, 1), 255) / 1000  # the driver accepts 1..255 ms (AN232B-04, "Adjusting ... Latency")

    def schedule(self, bytes_at: list[tuple[float, bytes]]) -> list[tuple[float, bytes]]:
        """(time the host gets them, bytes) for bytes leaving the motors at the given times."""
        latency = self.latency_s
        out: list[tuple[float, bytes]] = []
        buffer = b""
        for t, chunk in bytes_at:
            for b in range(len(chunk)):  # each byte lands at its own time; a full packet goes at once
                buffer += chunk[b:b + 1]
                if len(buffer) == FTDI_PACKET:
                    out.append((t, buffer))
                    self._last_sent, buffer = t, b""
        if buffer:
            end = bytes_at[-1][0]
            periods = max(1, math.ceil((end - self._last_sent) / latency))
            self._last_sent += periods * latency
            out.append((self._last_sent, buffer))
        return out


class DynamixelBus:
    def __init__(self, port: str | Path | None = None, positions: dict[int, int] | None = None,
                 latency_timer_ms: int = FTDI_DEFAULT_LATENCY_MS):
        self._dir = tempfile.mkdtemp(prefix="teleprev-dxl-")
        self.port = str(port) if port is not None else str(Path(self._dir) / "ttyLEAP")
        # the adapter's sysfs attribute (/sys/bus/usb-serial/devices/ttyUSBn/latency_timer on a real one)
        self.latency_timer_path = Path(self._dir) / "latency_timer"
        self.latency_timer_path.write_text(f"{latency_timer_ms}\n")
        self.adapter = FtdiAdapter(self.latency_timer_path)
        self.motors = {i: Motor(i, (positions or {}).get(i, OPEN_HAND)) for i in MOTOR_IDS}
        self._lock = threading.Lock()
        self._master = -1
        self._slave = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.bad_crc = False
        self.requests: Counter[int] = Counter()
        self.goal_writes = 0  # sync writes of the goal position
        # The host's tty layer handing the replies on late (a kernel worker pushes received bytes to the
        # port; under load it waits like any process): every reply reaches the host this much later.
        self.host_delay_s = 0.0
        self.goal_arrivals_ns: list[int] = []  # time.monotonic_ns() each goal-position sync write was read
        self.unheard = 0  # requests sent at a baud rate no motor listens at
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
        try:  # never over something that is there: a file, or a device node like /dev/ttyUSB0
            link.symlink_to(os.ttyname(slave))
        except OSError as exc:
            os.close(master)
            os.close(slave)
            why = "it already exists" if link.is_symlink() or link.exists() else exc.strerror
            raise EmulatorError(f"cannot put the emulated bus at {link}: {why}; pick a path that does not exist "
                                "(or leave out --port)") from None
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
        shutil.rmtree(self._dir, ignore_errors=True)

    def __enter__(self) -> DynamixelBus:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def rig_keys(self, name: str = "hand") -> str:
        # A real adapter's latency timer is found from the port in sysfs; a pseudo-terminal has none there.
        return (f'[devices.{name}]\nplugin = "leap.hand"\nport = "{self.port}"\n'
                f'latency_timer_path = "{self.latency_timer_path}"\n')

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
            elif kind == "lost_reply":
                m.lose_next = True
            elif kind == "stale_reply":
                m.stale_next = True

    def operator_clear(self) -> None:
        """The hand power-cycled and the adapter back in: no hardware errors, every motor answers."""
        with self._lock:
            self.bad_crc = False
            for m in self.motors.values():
                m.silent = m.lose_next = m.stale_next = False
                m.set(wire.HARDWARE_ERROR_STATUS, 0)
                m.reboot()
        if not self.plugged:
            self.plug()

    def positions(self) -> dict[int, int]:
        with self._lock:
            now = time.monotonic()
            for m in self.motors.values():
                m.step(now)
            return {i: m.get(wire.PRESENT_POSITION) for i, m in self.motors.items()}

    # ---- the bus ---------------------------------------------------------------------------------------
    def _port_baud(self, slave: int) -> int:
        try:
            speed = termios.tcgetattr(slave)[4]
        except termios.error:
            return 0
        return next((b for b in wire.BAUD_RATES.values() if getattr(termios, f"B{b}", None) == speed), 0)

    def _serve(self, master: int) -> None:
        # Real motors answer whatever the host does: where allowed (root), this thread runs before the host's
        # other work (it mostly sleeps in select), at REPLY_PRIORITY or the real-time priority its process
        # already has (tests/helpers/emulated_rig.py: 40), never lower: at 10 in a process at 40, requests
        # waited up to 45 ms behind the command path's processes for this thread to read them, so the SDK's
        # 34.6 ms wait ran out on replies a bus would have sent in 2 ms (bench/hardware.py's read misses).
        try:
            me = threading.get_native_id()
            held = os.sched_getparam(me).sched_priority if os.sched_getscheduler(me) == os.SCHED_FIFO else 0
            os.sched_setscheduler(me, os.SCHED_FIFO, os.sched_param(max(REPLY_PRIORITY, held)))
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
            arrived = time.monotonic()
            baud = self._port_baud(self._slave)
            replies: list[tuple[Motor, bytes]] = []
            for dxl_id, instruction, params in reader.feed(data):
                replies += self._answer(dxl_id, instruction, params, baud)
            if not replies:
                continue
            # Each motor speaks after its return delay, once the one before it is done (half duplex).
            t, bytes_at = arrived + self.host_delay_s, []
            for m, out in replies:
                t += m.return_delay_s + len(out) * 10 / baud
                bytes_at.append((t, out))
            for due, chunk in self.adapter.schedule(bytes_at):
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
                try:
                    os.write(master, chunk)
                except OSError:
                    return

    def _status(self, m: Motor, error: int, data: bytes = b"") -> bytes:
        return wire.status(m.id, error | (wire.ALERT if m.hardware_error else 0), data, corrupt=self.bad_crc)

    def _listening(self, baud: int) -> list[Motor]:
        return [m for m in self.motors.values() if not m.silent and wire.BAUD_RATES.get(m.get(wire.BAUD_RATE)) == baud]

    def _answer(self, dxl_id: int, instruction: int | None, params: bytes, baud: int) -> list[tuple[Motor, bytes]]:
        """The status packets a request gets, in the order the motors send them."""
        with self._lock:
            listening = {m.id: m for m in self._listening(baud)}
            if not listening:
                self.unheard += 1
                return []
            if instruction is None:
                self.corrupt_requests += 1
                m = listening.get(dxl_id)
                return [(m, self._status(m, wire.CRC_ERROR))] if m else []
            self.requests[instruction] += 1
            if dxl_id == wire.BROADCAST:
                return self._broadcast(instruction, params, listening)
            m = listening.get(dxl_id)
            if m is None:
                return []
            error, data = self._unicast(m, instruction, params)
            if not m.answers(instruction):
                return []
            return self._as_heard(m, self._status(m, error, data))

    def _as_heard(self, m: Motor, packet: bytes) -> list[tuple[Motor, bytes]]:
        """A motor's status packet as the host gets it, after the injected lost_reply and stale_reply."""
        if m.lose_next:
            m.lose_next = False
            return []
        if m.stale_next:
            m.stale_next = False
            return [(m, self._status(m, 0, bytes([m.hardware_error]))), (m, packet)]
        return [(m, packet)]

    def _unicast(self, m: Motor, instruction: int, params: bytes) -> tuple[int, bytes]:
        if instruction == wire.PING:
            return 0, struct.pack("<HB", m.get(wire.MODEL_NUMBER), m.get(wire.FIRMWARE_VERSION))
        if instruction == wire.READ and len(params) >= 4:
            address, size = struct.unpack("<HH", params[:4])
            return m.read(address, size)
        if instruction == wire.WRITE and len(params) >= 3:
            return m.write(struct.unpack("<H", params[:2])[0], params[2:]), b""
        if instruction == wire.REBOOT:
            m.reboot()  # the status packet goes before the restart (e-Manual, Reboot)
            return 0, b""
        return wire.INSTRUCTION_ERROR, b""

    def _broadcast(self, instruction: int, params: bytes, listening: dict[int, Motor]) -> list[tuple[Motor, bytes]]:
        if instruction == wire.PING:  # every motor answers, in ID order
            return [(m, self._status(m, *self._unicast(m, wire.PING, b""))) for _, m in sorted(listening.items())]
        if instruction in (wire.WRITE, wire.REBOOT):  # every motor acts, none answers
            for m in listening.values():
                self._unicast(m, instruction, params)
            return []
        if instruction == wire.SYNC_WRITE and len(params) >= 4:
            address, size = struct.unpack("<HH", params[:4])
            body = params[4:]
            for k in range(0, len(body) - size, size + 1):
                m = listening.get(body[k])
                if m is not None:
                    m.write(address, body[k + 1:k + 1 + size])
            if address == wire.GOAL_POSITION[0]:
                self.goal_writes += 1
                self.goal_arrivals_ns.append(time.monotonic_ns())
            return []
        if instruction == wire.BULK_WRITE:
            for dxl_id, address, data in _bulk_items(params, with_data=True):
                if dxl_id in listening:
                    listening[dxl_id].write(address, data)
            return []
        if instruction in (wire.SYNC_READ, wire.FAST_SYNC_READ) and len(params) >= 4:
            address, size = struct.unpack("<HH", params[:4])
            asked = [(i, address, size) for i in params[4:]]
        elif instruction in (wire.BULK_READ, wire.FAST_BULK_READ):
            asked = [(i, a, n) for i, a, n in _bulk_items(params, with_data=False)]
        else:
            return []
        fast = instruction in (wire.FAST_SYNC_READ, wire.FAST_BULK_READ)
        answers = []
        for i, address, size in asked:
            m = listening.get(i)
            if m is None or not m.answers(instruction):
                if fast:
                    break  # one packet the motors fill in turn: it ends where a motor does not speak
                continue
            answers.append((m, *m.read(address, size)))
        if not fast:  # each motor its own status packet, in the order asked (e-Manual, Sync Read / Bulk Read)
            return [heard for m, error, data in answers for heard in self._as_heard(m, self._status(m, error, data))]
        if not answers:
            return []
        parts = [(error | (wire.ALERT if m.hardware_error else 0), m.id, data) for m, error, data in answers]
        packet = wire.fast_status(parts, corrupt=self.bad_crc)
        if len(answers) < len(asked):
            packet = packet[:-2]  # cut short: no last CRC
        return [(answers[0][0], packet)]


def _bulk_items(params: bytes, with_data: bool):
    """(id, address, size) or (id, address, data) of a bulk read / write's parameters."""
    k = 0
    while k + 5 <= len(params):
        dxl_id, address, size = params[k], *struct.unpack("<HH", params[k + 1:k + 5])
        k += 5
        if with_data:
            yield dxl_id, address, params[k:k + size]
            k += size
        else:
            yield dxl_id, address, size
