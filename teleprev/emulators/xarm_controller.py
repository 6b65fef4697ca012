"""An emulated xArm control box that xarm-python-sdk drives unmodified.

    with XArmController(host="127.0.0.1", dof=6).start() as box:   # ports 502, 30001-30003 on host
        api = XArmAPI(box.host, is_radian=True)                    # the real SDK
        ...
        box.inject("collision")                                    # error 31: the arm stops
        box.operator_clear()                                       # the operator clears it (UFactory Studio)

The SDK only talks to port 502 (and the report ports), so several controllers run side by side on
different loopback addresses (`host=None` picks a free 127.x.y.z); those ports need root.

What the box does, each from the SDK's source (xarm/) or UFactory's documents, never from our plugin:
- states: set_mode leaves the arm in state 5, "mode changed, not ready", until set_state(0) (xarm_ros
  RobotMsg.msg; the SDK treats 4 and 5 as not ready, x3/base.py); set_state(4) and set_state(6), the
  "deceleration stop" (XArmAPI.set_state), stop the arm: state 4.
- joint limits: the SDK's table for the arm's series (xarm/core/config/x_config.py JOINT_LIMITS; an SN from
  XI1305 on is the "_1305" row, x3/xarm.py _is_out_of_joint_range): a target past them is error 23.
- servo mode (mode 1): a servo cycle of `servo_period_s` runs only the latest target that arrived in it,
  judged on the box's cycle at the stream's pace (a stall, an early target, a burst as the motors run
  them): error 24 for a joint too fast, error 60 for the flange, jolts counted (xarm_servo.ServoCycle,
  `box.servo`); every target's arrival is stamped (`arrivals`).
- position mode (mode 0): set_servo_angle, set_position and reset move the arm at the requested speed
  (xarm_moves.PositionMoves).
- the TCP pose (get_position, the reports) is forward kinematics of our URDF (xarm_kinematics);
  get_joint_states answers positions, velocities and efforts; reports on 30001/30002 (5 Hz) and 30003
  (100 Hz) (xarm_reports.ReportStreams).
This class is the box's state machine (states, mode, errors) and its port 502: it answers each register and
hands motion to the parts above.

Injected faults (`inject(kind)`): collision (error 31), joint_limit (error 23), estop (error 1, motors
off until the button is released), drop (every TCP connection closed; reconnecting is allowed),
silent_report (the open report connections stop sending), slow_replies (each reply held back).
"""

from __future__ import annotations

import struct
import threading
import time
from collections import Counter

import numpy as np

from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.listening import Listener, free_loopback_host, listen
from teleprev.emulators.xarm_kinematics import ArmKinematics, joint_table
from teleprev.emulators.xarm_moves import PositionMoves
from teleprev.emulators.xarm_reports import REPORT_PORTS, ReportStreams
from teleprev.emulators.xarm_servo import MAX_TCP_SPEED_MM_S, SERVO_PERIOD_S, ServoCycle, ServoFault

FAULTS = ("collision", "joint_limit", "estop", "drop", "silent_report", "slow_replies")
HOME = (0.0, -0.27, -0.11, 0.0, -0.85, -1.571)  # the sim arm's home: palm forward, the TCP near (0.29, 0, 0.31) m
FIRMWARE = "2.6.0"


class XArmController:
    """The box: its states, mode and errors, and port 502's registers; motion is the servo cycle's
    (`servo`) and the position moves' (`moves`), the reports are `reports`'."""

    def __init__(self, host: str | None = "127.0.0.1", dof: int = 6, home: tuple[float, ...] | None = None,
                 report_period_s: float = wire.REPORT_PERIOD_S, slow_reply_s: float = 0.5, series: int = 1303,
                 servo_period_s: float = SERVO_PERIOD_S, max_tcp_speed_mm_s: float = MAX_TCP_SPEED_MM_S):
        if dof not in (6, 7):
            raise ValueError(f"dof must be 6 or 7, got {dof}")
        self.kinematics = ArmKinematics(dof)
        self.lower, self.upper = joint_table(dof, series)
        self.requested_host = host
        self.host = host or ""
        self.dof = dof
        self.slow_reply_s = slow_reply_s
        start = np.array((HOME + (0.0,))[:dof] if home is None else home, dtype=float)
        if start.shape != (dof,):
            raise ValueError(f"home needs {dof} values, got {len(start)}")
        self.angles = np.clip(start, self.lower, self.upper)
        self.speeds = np.zeros(dof)
        self.sn = f"XI{series:04d}EMU{dof:04d}"
        self.version = f"{dof},{dof},{self.sn},AC1303EMU0001,v{FIRMWARE}"
        self._lock = threading.Lock()
        self.state = wire.STOPPED
        self.mode = 0
        self.enabled = False
        self.error = 0
        self.warning = 0
        self.estop_pressed = False
        self._slow_until = 0.0
        self._report_counter = 0
        self.servo = ServoCycle(self.kinematics, self.lower, self.upper, servo_period_s, max_tcp_speed_mm_s)
        self.moves = PositionMoves(self.kinematics, self.lower, self.upper)
        self.reports = ReportStreams(self.report_state, report_period_s)
        self.requests: Counter[int] = Counter()  # register -> requests served
        self.unknown: Counter[int] = Counter()  # registers the emulator does not implement
        self.faults: list[tuple[int, str, int]] = []  # (monotonic ns, what, error code) for every latched error
        self.injected: list[tuple[int, str]] = []
        self._listeners: list[Listener] = []

    @property
    def commands(self):
        """The servo targets the arm ran (ServoCycle.commands)."""
        return self.servo.commands

    @property
    def arrivals(self):
        """Every servo target that reached the box (ServoCycle.arrivals)."""
        return self.servo.arrivals

    @property
    def judged(self):
        return self.servo.judged

    # ---- lifecycle ---------------------------------------------------------------------------------
    def start(self) -> XArmController:
        ports = (wire.COMMAND_PORT, *REPORT_PORTS)
        self.host = self.requested_host or free_loopback_host(ports)
        why = " (the xArm SDK only talks to ports 502 and 30001-30003)"
        socks = []
        try:
            for p in ports:
                socks.append(listen(self.host, p, why))
        except Exception:
            for s in socks:
                s.close()
            raise
        self._listeners = [Listener(socks[0], self._serve_commands, f"xarm-{self.host}-502").start()]
        for sock, port in zip(socks[1:], REPORT_PORTS):
            self._listeners.append(Listener(sock, lambda c, port=port: self.reports.serve(c, port),
                                            f"xarm-{self.host}-{port}").start())
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
        return f'[devices.{name}]\nplugin = "xarm.arm"\nhost = "{self.host}"\ndof = {self.dof}\n'

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
            for listener in self._listeners:
                listener.drop_all()
        elif kind == "silent_report":
            self.reports.silence(self._listeners[1:])
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
        self._advance(time.monotonic_ns())
        self.error = code
        self.state = wire.STOPPED
        self.speeds[:] = 0.0
        self.moves.clear()
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
            frames, buf = wire.split_frames(buf + chunk)
            for frame in frames:
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
        self._advance(now)
        if register == wire.GET_VERSION:
            return self.version.encode().ljust(40, b"\0"), False
        if register == wire.GET_ROBOT_SN:
            return f"{self.sn}\0AC1303EMU0001\0".encode().ljust(40, b"\0"), False
        if register == wire.GET_STATE:
            return bytes([self.state]), False
        if register == wire.GET_ERROR:
            return bytes([self.error, self.warning]), False
        if register == wire.GET_CMDNUM:
            return struct.pack(">H", len(self.moves)), False
        if register == wire.GET_JOINT_POS:
            if not data:
                return wire.floats(self.angles, 7), False
            rows = (self.angles, self.speeds, np.zeros(self.dof))[:max(1, min(3, data[0] & 0x0F))]
            return b"".join(wire.floats(r, 7) for r in rows), False
        if register == wire.GET_TCP_POSE:
            return wire.floats(self.pose(), 6), False
        if register == wire.GET_TCP_POSE_AA:
            return wire.floats(self.kinematics.pose_axis_angle(self.angles), 6), False
        if register == wire.MOTION_EN and len(data) >= 2:
            if self.estop_pressed:
                return b"", True
            self.enabled = bool(data[1])
            if not self.enabled:
                self.state = wire.STOPPED
            return b"", False
        if register == wire.SET_MODE and len(data) >= 1:
            self.mode = data[0]
            self.state = wire.CONFIG_CHANGED  # not ready until set_state(0)
            self.moves.clear()
            self.servo.reset()
            return b"", False
        if register == wire.SET_STATE and len(data) >= 1:
            return b"", self._set_state(data[0])
        if register == wire.CLEAN_ERR:
            if not self.estop_pressed:
                self.error = 0
            return b"", False
        if register == wire.CLEAN_WAR:
            self.warning = 0
            return b"", False
        if register == wire.SET_FEEDBACK_TYPE:
            return b"", False  # accepted; motion-finished feedback packets are not sent (the SDK then polls state)
        if register == wire.MOVE_SERVOJ and len(data) >= 40:
            # Refused for an error or for not being ready, the reply's state bits say so; in another mode the
            # target is invalid.
            self._servo(np.array(struct.unpack("<10f", data[:40])[:self.dof], dtype=float), now)
            return b"", self.mode != wire.SERVO_MODE
        if register in (wire.MOVE_JOINT, wire.MOVE_HOME, wire.MOVE_LINE):
            if not self._ready(wire.POSITION_MODE) or not self.moves.add(register, data, self.angles, now):
                return b"", True
            self.state = wire.MOVING
            return b"", False
        self.unknown[register] += 1
        return b"", True

    def _set_state(self, wanted: int) -> bool:
        """Whether set_state(wanted) is refused (invalid)."""
        if wanted == 0:
            if self.error or not self.enabled:
                return True
            self.state = wire.MOVING if self.moves else wire.READY
            return False
        if wanted in (wire.STOPPED, wire.DECELERATION_STOP):  # both end with the arm stopped, its queue emptied
            self.moves.clear()
            self.speeds[:] = 0.0
            self.state = wire.STOPPED
            return False
        if wanted == wire.PAUSED:
            self.state = wanted
            return False
        return True

    def _ready(self, mode: int) -> bool:
        return (not self.error and self.enabled and self.mode == mode
                and self.state in (wire.READY, wire.MOVING))

    def pose(self) -> list[float]:
        """The TCP pose as the box reports it: x, y, z in mm, roll, pitch, yaw in rad."""
        return self.kinematics.pose(self.angles)

    # ---- motion ------------------------------------------------------------------------------------
    def _advance(self, now_ns: int) -> None:
        """Bring the arm to `now`: position-mode moves along, a quiet servo stream back to READY."""
        where = self.moves.advance(now_ns)
        if where is not None:
            self.angles, self.speeds = where.angles, where.speeds
            if where.done and self.state == wire.MOVING:
                self.state = wire.READY
        if self.state == wire.MOVING and self.mode == wire.SERVO_MODE and self.servo.quiet(now_ns):
            self.state = wire.READY
            self.speeds[:] = 0.0

    def _servo(self, target: np.ndarray, now: int) -> None:
        """A servo target: run by the servo cycle when the arm is ready for it; one it must not follow
        faults the arm."""
        if not self._ready(wire.SERVO_MODE):
            self.servo.refuse(target, now)
            return
        ran = self.servo.run(target, now, self.angles)
        if isinstance(ran, ServoFault):
            self._latch_locked(ran.code, ran.what)
            return
        self.angles, self.speeds = ran.target, ran.speeds
        self.state = wire.MOVING

    # ---- ports 30001-30003 -------------------------------------------------------------------------
    def report_state(self) -> wire.ReportState:
        with self._lock:
            self._advance(time.monotonic_ns())
            self._report_counter += 1
            pad = 7 - self.dof
            return wire.ReportState(
                state=self.state, mode=self.mode, angles=np.concatenate([self.angles, np.zeros(pad)]),
                pose=np.array(self.pose()), speeds=np.concatenate([self.speeds, np.zeros(pad)]),
                motors_enabled=self.enabled, error=self.error, warning=self.warning, axis=self.dof,
                robot_type=self.dof, version=f"v{FIRMWARE}", counter=self._report_counter)
