"""An emulated xArm control box that xarm-python-sdk drives unmodified.

    with XArmController(host="127.0.0.1", dof=6).start() as box:   # ports 502, 30001, 30002 on host
        api = XArmAPI(box.host, is_radian=True)                    # the real SDK
        ...
        box.inject("collision")                                    # error 31: the arm stops
        box.operator_clear()                                       # the operator clears it (UFactory Studio)

The SDK only talks to port 502 (and the report ports), so several controllers run side by side on
different loopback addresses (`host=None` picks a free 127.x.y.z); those ports need root.

Servo mode as the controller runs it (mode 1, state 0 after motion enable): each set_servo_angle_j
target is taken at once, with no smoothing. The controller faults, stops the arm where it is and latches
the error (state 4, the error bit in every reply, the code in the report) when a target is outside a
joint's limits (error 23) or further from the last than the joint's speed limit allows in the time since
it (taken as 10 to 30 ms: a 100 Hz stream, late by up to two periods; error 24). Acceleration and jerk are judged on the host, on the commands'
stamps (teleprev.devices.ServoStreamRule), since a controller only sees when the bytes arrived.

Injected faults (`inject(kind)`): collision (error 31), joint_limit (error 23), estop (error 1, motors
off until the button is released), drop (every TCP connection closed; reconnecting is allowed),
silent_report (the open report connections stop sending), slow_replies (each reply held back).
"""

from __future__ import annotations

import struct
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.listening import Listener, free_loopback_host, listen

FAULTS = ("collision", "joint_limit", "estop", "drop", "silent_report", "slow_replies")
HOME = (0.0, -0.27, -0.11, 0.0, -0.85, -1.571)  # the sim arm's home: palm forward, the TCP near (0.40, 0, 0.30) m
FIRMWARE = "2.6.0"
SERVO_WINDOW_S = (0.01, 0.03)  # a servo target is taken to be meant over the time since the last one, within these
SPEED_TOLERANCE = 0.10
REPLY_TIMEOUT_S = 0.3  # the rig keys' reply_timeout_s: the emulator shares the host's cores with the session
IDLE_AFTER_S = 0.2  # a servo-mode arm with no new target for this long reports READY again


@dataclass(frozen=True)
class ReceivedCommand:
    received_ns: int  # time.monotonic_ns() when the controller read it
    target: np.ndarray


class XArmController:
    def __init__(self, host: str | None = "127.0.0.1", dof: int = 6, home: tuple[float, ...] | None = None,
                 report_period_s: float = wire.REPORT_PERIOD_S, slow_reply_s: float = 0.5):
        from teleprev.robot.model import load_robot

        if dof not in (6, 7):
            raise ValueError(f"dof must be 6 or 7, got {dof}")
        model = load_robot(f"xarm{dof}")
        idx = model.indices(tuple(f"joint{i}" for i in range(1, dof + 1)))
        self.lower, self.upper, self.max_speed = model.lower[idx], model.upper[idx], model.velocity_limit[idx]
        self.requested_host = host
        self.host = host or ""
        self.dof = dof
        self.report_period_s = report_period_s
        self.slow_reply_s = slow_reply_s
        start = np.array((HOME + (0.0,))[:dof] if home is None else home, dtype=float)
        if start.shape != (dof,):
            raise ValueError(f"home needs {dof} values, got {len(start)}")
        self.angles = np.clip(start, self.lower, self.upper)
        self.speeds = np.zeros(dof)
        self.version = f"{dof},{dof},XI1303EMU{dof:04d},AC1303EMU0001,v{FIRMWARE}"
        self._lock = threading.Lock()
        self.state = wire.STOPPED
        self.mode = 0
        self.enabled = False
        self.error = 0
        self.warning = 0
        self.estop_pressed = False
        self._last_command_ns = 0
        self._slow_until = 0.0
        self._silenced: set = set()
        self._report_counter = 0
        self.commands: deque[ReceivedCommand] = deque(maxlen=200_000)
        self.requests: Counter[int] = Counter()  # register -> requests served
        self.unknown: Counter[int] = Counter()  # registers the emulator does not implement
        self.faults: list[tuple[int, str, int]] = []  # (monotonic ns, what, error code) for every latched error
        self.injected: list[tuple[int, str]] = []
        self._listeners: list[Listener] = []

    # ---- lifecycle ---------------------------------------------------------------------------------
    def start(self) -> XArmController:
        ports = (wire.COMMAND_PORT, wire.REPORT_NORMAL_PORT, wire.REPORT_RICH_PORT)
        self.host = self.requested_host or free_loopback_host(ports)
        why = " (the xArm SDK only talks to ports 502, 30001 and 30002)"
        socks = []
        try:
            for p in ports:
                socks.append(listen(self.host, p, why))
        except Exception:
            for s in socks:
                s.close()
            raise
        self._listeners = [
            Listener(socks[0], self._serve_commands, f"xarm-{self.host}-502").start(),
            Listener(socks[1], lambda c: self._serve_reports(c, wire.NORMAL_REPORT_SIZE), f"xarm-{self.host}-30001").start(),
            Listener(socks[2], lambda c: self._serve_reports(c, wire.RICH_REPORT_SIZE), f"xarm-{self.host}-30002").start(),
        ]
        return self

    def stop(self) -> None:
        for listener in self._listeners:
            listener.stop()
        self._listeners = []

    def __enter__(self) -> XArmController:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def rig_keys(self, name: str = "arm") -> str:
        # The controller answers from a thread on this host's cores: a busy host needs a longer reply
        # timeout than a real controller's 0.1 s (the injected slow replies, 0.5 s, still fault).
        return (f'[devices.{name}]\nplugin = "xarm.arm"\nhost = "{self.host}"\ndof = {self.dof}\n'
                f'reply_timeout_s = {REPLY_TIMEOUT_S:g}\n')

    @property
    def connections(self) -> int:
        return sum(len(listener.connections) for listener in self._listeners[:1])

    # ---- what an operator or a test does to the box ------------------------------------------------
    def inject(self, kind: str) -> None:
        if kind not in FAULTS:
            raise ValueError(f"unknown fault {kind!r} (one of {', '.join(FAULTS)})")
        self.injected.append((time.monotonic_ns(), kind))
        if kind == "collision":
            self._latch(wire.COLLISION, "collision detected")
        elif kind == "joint_limit":
            self._latch(wire.JOINT_LIMIT, "a joint passed its limit")
        elif kind == "estop":
            with self._lock:
                self.estop_pressed = True
                self.enabled = False
            self._latch(wire.ESTOP, "emergency stop pressed")
        elif kind == "drop":
            self._listeners[0].drop_all()
            for listener in self._listeners[1:]:
                listener.drop_all()
        elif kind == "silent_report":
            with self._lock:
                for listener in self._listeners[1:]:
                    self._silenced.update(listener.connections)
        elif kind == "slow_replies":
            with self._lock:
                self._slow_until = time.monotonic() + 1.0

    def operator_clear(self) -> None:
        """What an operator does after a stop: release the e-stop and clear the error (UFactory Studio).
        The arm stays stopped until a client enables it again (motion enable, mode, state 0)."""
        with self._lock:
            self.estop_pressed = False
            self.error = 0
            self._slow_until = 0.0

    def _latch(self, code: int, what: str) -> None:
        with self._lock:
            self._latch_locked(code, what)

    def _latch_locked(self, code: int, what: str) -> None:
        self.error = code
        self.state = wire.STOPPED
        self.speeds[:] = 0.0
        self.faults.append((time.monotonic_ns(), what, code))

    # ---- port 502 ----------------------------------------------------------------------------------
    def _serve_commands(self, conn) -> None:
        buf = b""
        listener = self._listeners[0]
        while not listener.stopped:
            try:
                chunk = conn.recv(4096)
            except TimeoutError:
                continue
            if not chunk:
                return
            buf += chunk
            while len(buf) >= 6:
                length = struct.unpack(">H", buf[4:6])[0]
                if len(buf) < 6 + length:
                    break
                frame, buf = buf[:6 + length], buf[6 + length:]
                out = self._handle(frame)
                if out:
                    delay = self._reply_delay()
                    if delay:
                        time.sleep(delay)
                    conn.sendall(out)

    def _reply_delay(self) -> float:
        with self._lock:
            return self.slow_reply_s if time.monotonic() < self._slow_until else 0.0

    def _handle(self, frame: bytes) -> bytes:
        transaction, protocol, length, register = wire.HEADER.unpack(frame[:7])
        data = frame[7:]
        if protocol not in (2, 3):  # a heartbeat (protocol 1) or a standard Modbus request: not modelled
            return b""
        now = time.monotonic_ns()
        with self._lock:
            self.requests[register] += 1
            out, invalid = self._register(register, data, now)
            flags = ((wire.ERROR_BIT if self.error else 0) | (wire.WARNING_BIT if self.warning else 0)
                     | (wire.NOT_READY_BIT if self.state >= wire.STOPPED or not self.enabled else 0)
                     | (wire.INVALID_BIT if invalid else 0))
        return wire.reply(transaction, protocol, register, flags, out)

    def _register(self, register: int, data: bytes, now: int) -> tuple[bytes, bool]:
        """(reply data, invalid) for one request; runs under the lock."""
        if register == wire.GET_VERSION:
            return self.version.encode().ljust(40, b"\0"), False
        if register == wire.GET_ROBOT_SN:
            return b"XI1303EMU0001\0AC1303EMU0001\0".ljust(40, b"\0"), False
        if register == wire.GET_STATE:
            self._settle(now)
            return bytes([self.state]), False
        if register == wire.GET_ERROR:
            return bytes([self.error, self.warning]), False
        if register == wire.GET_CMDNUM:
            return struct.pack(">H", 0), False
        if register == wire.GET_JOINT_POS:
            return wire.floats(self.angles, 7), False
        if register in (wire.GET_TCP_POSE, wire.GET_TCP_POSE_AA):
            return wire.floats([], 6), False
        if register == wire.MOTION_EN and len(data) >= 2:
            if self.estop_pressed:
                return b"", True
            self.enabled = bool(data[1])
            if not self.enabled:
                self.state = wire.STOPPED
            return b"", False
        if register == wire.SET_MODE and len(data) >= 1:
            self.mode = data[0]
            return b"", False
        if register == wire.SET_STATE and len(data) >= 1:
            wanted = data[0]
            if wanted == 0:
                if self.error or not self.enabled:
                    return b"", True
                self.state = wire.READY
            elif wanted in (wire.PAUSED, wire.STOPPED):
                self.state = wanted
            return b"", False
        if register == wire.CLEAN_ERR:
            if not self.estop_pressed:
                self.error = 0
            return b"", False
        if register == wire.CLEAN_WAR:
            self.warning = 0
            return b"", False
        if register == wire.MOVE_SERVOJ and len(data) >= 40:
            # Refused for an error or for not being ready, the reply's state bits say so; in another mode the
            # target is invalid.
            self._servo(np.array(struct.unpack("<10f", data[:40])[:self.dof], dtype=float), now)
            return b"", self.mode != wire.SERVO_MODE
        self.unknown[register] += 1
        return b"", True

    def _servo(self, target: np.ndarray, now: int) -> None:
        """Take a servo target at once, unless the arm is not ready; a target the arm must not follow faults it."""
        if self.error or not self.enabled or self.mode != wire.SERVO_MODE or self.state not in (wire.READY, wire.MOVING):
            return
        self.commands.append(ReceivedCommand(now, target))
        outside = (target < self.lower - 1e-6) | (target > self.upper + 1e-6)
        if outside.any():
            j = int(np.argmax(outside))
            self._latch_locked(wire.JOINT_LIMIT, f"joint{j + 1} target {target[j]:.4f} outside "
                                                 f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")
            return
        dt = min(max((now - self._last_command_ns) / 1e9, SERVO_WINDOW_S[0]), SERVO_WINDOW_S[1])
        speed = np.abs(target - self.angles) / dt
        over = speed > self.max_speed * (1.0 + SPEED_TOLERANCE)
        if over.any():
            j = int(np.argmax(speed / self.max_speed))
            self._latch_locked(wire.SPEED_LIMIT, f"joint{j + 1} commanded at {speed[j]:.3g} rad/s "
                                                 f"(limit {self.max_speed[j]:g})")
            return
        self.speeds = (target - self.angles) / dt
        self.angles = target
        self.state = wire.MOVING
        self._last_command_ns = now

    def _settle(self, now: int) -> None:
        if self.state == wire.MOVING and now - self._last_command_ns > IDLE_AFTER_S * 1e9:
            self.state = wire.READY
            self.speeds[:] = 0.0

    # ---- ports 30001 / 30002 -----------------------------------------------------------------------
    def report(self, size: int = wire.RICH_REPORT_SIZE) -> bytes:
        with self._lock:
            self._settle(time.monotonic_ns())
            self._report_counter += 1
            pad = 7 - self.dof
            r = wire.ReportState(
                state=self.state, mode=self.mode, angles=np.concatenate([self.angles, np.zeros(pad)]),
                speeds=np.concatenate([self.speeds, np.zeros(pad)]), motors_enabled=self.enabled, error=self.error,
                warning=self.warning, axis=self.dof, robot_type=self.dof, version=f"v{FIRMWARE}",
                counter=self._report_counter)
        return wire.pack_report(r, size)

    def _serve_reports(self, conn, size: int) -> None:
        listener = self._listeners[1] if size == wire.NORMAL_REPORT_SIZE else self._listeners[2]
        next_t = time.monotonic()
        while not listener.stopped:
            with self._lock:
                silent = conn in self._silenced
            if not silent:
                conn.sendall(self.report(size))
            next_t += self.report_period_s
            time.sleep(max(0.0, next_t - time.monotonic()))
            if conn.fileno() < 0:
                return
