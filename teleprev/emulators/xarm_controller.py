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
- servo mode (mode 1): a servo cycle of `servo_period_s` runs only the latest target that arrived in it; each
  target is judged against the one that ran before it, on the times the targets arrived (the box has no
  other clock for them): a joint faster than its limit (pi rad/s, 10% margin) is error 24, the flange
  faster than `max_tcp_speed_mm_s` is error 60 ("Linear speed exceeded limit in servo_j mode", x_code).
  Acceleration and jerk have no controller error code; they are judged on the same arrivals and counted as
  jolts (`judged`, `jolts`), the figures a real arm feels.
- position mode (mode 0): set_servo_angle, set_position and reset (move_gohome: all joints to 0) move the arm
  at the requested speed, in state 1 until done, then state 2 (what the SDK's wait=True polls for).
- the TCP pose (get_position, the reports) is forward kinematics of our URDF (at the zero pose [207, 0, 112]
  mm, as UFactory gives the xArm6's initial position); get_joint_states answers positions, velocities and
  efforts; reports on 30001/30002 (5 Hz) and 30003 (100 Hz).
Every servo target's arrival is stamped (`arrivals`), so a bench can compute arrival gaps, lateness and
targets per servo cycle.

Injected faults (`inject(kind)`): collision (error 31), joint_limit (error 23), estop (error 1, motors
off until the button is released), drop (every TCP connection closed; reconnecting is allowed),
silent_report (the open report connections stop sending), slow_replies (each reply held back).
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections import Counter, deque
from dataclasses import dataclass, field

import numpy as np

from teleprev.devices.servo_limits import STREAM_GAP_NS
from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.listening import Listener, free_loopback_host, listen

FAULTS = ("collision", "joint_limit", "estop", "drop", "silent_report", "slow_replies")
HOME = (0.0, -0.27, -0.11, 0.0, -0.85, -1.571)  # the sim arm's home: palm forward, the TCP near (0.29, 0, 0.31) m
FIRMWARE = "2.6.0"
SERVO_PERIOD_S = 0.004  # the box's servo cycle: 250 Hz, UFactory's maximum command rate on port 502
SPEED_TOLERANCE = 0.10
MAX_TCP_SPEED_MM_S = 1000.0  # xArm6 / xArm7 maximum TCP speed, 1 m/s (UFactory specifications)
MAX_ACCELERATION, MAX_JERK = 10.0, 500.0  # rad/s^2, rad/s^3: what jolts are counted against (no error code)
IDLE_AFTER_S = 0.2  # a servo-mode arm with no new target for this long reports READY again
TWO_PI = 2 * math.pi
# xarm/core/config/x_config.py XCONF.Robot.JOINT_LIMITS: (axis, series from XI1305 on) -> per-joint (low, high)
JOINT_TABLE = {
    (6, False): ((-TWO_PI, TWO_PI), (-2.059488, 2.094395), (-3.92699, 0.191986), (-TWO_PI, TWO_PI),
                 (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (6, True): ((-TWO_PI, TWO_PI), (-2.042035, 2.024581), (-3.822271, 0.174532), (-TWO_PI, TWO_PI),
                (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (7, False): ((-TWO_PI, TWO_PI), (-2.059488, 2.094395), (-TWO_PI, TWO_PI), (-0.191986, 3.92699),
                 (-TWO_PI, TWO_PI), (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (7, True): ((-TWO_PI, TWO_PI), (-2.042035, 2.024581), (-TWO_PI, TWO_PI), (-0.10472, 3.92699),
                (-TWO_PI, TWO_PI), (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
}


@dataclass(frozen=True)
class ReceivedCommand:
    received_ns: int  # time.monotonic_ns() when the controller read it
    target: np.ndarray


@dataclass(frozen=True)
class Arrival:
    """A servo target as it reached the box: when, in which servo cycle, and whether it was taken."""

    received_ns: int
    cycle: int
    target: np.ndarray
    taken: bool  # False: the arm was not ready, or it faulted on it


@dataclass(frozen=True)
class Judgement:
    """How one target that ran compared with the one before it, on arrival times: each ratio is the value
    over its limit (speed: the fastest joint over its speed limit)."""

    received_ns: int
    speed_ratio: float
    accel_ratio: float
    jerk_ratio: float
    tcp_speed_mm_s: float


@dataclass
class Motion:
    """A position-mode move: from `start` to `goal` in joint space over `duration_s`."""

    start: np.ndarray
    goal: np.ndarray
    duration_s: float
    began: float = field(default=0.0)


def rpy_from_matrix(r: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw of R = Rz(yaw) Ry(pitch) Rx(roll), the xArm's TCP orientation convention."""
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])


class XArmController:
    def __init__(self, host: str | None = "127.0.0.1", dof: int = 6, home: tuple[float, ...] | None = None,
                 report_period_s: float = wire.REPORT_PERIOD_S, slow_reply_s: float = 0.5, series: int = 1303,
                 servo_period_s: float = SERVO_PERIOD_S, max_tcp_speed_mm_s: float = MAX_TCP_SPEED_MM_S):
        from teleprev.robot.model import load_robot

        if dof not in (6, 7):
            raise ValueError(f"dof must be 6 or 7, got {dof}")
        self.model = load_robot(f"xarm{dof}")
        idx = self.model.indices(tuple(f"joint{i}" for i in range(1, dof + 1)))
        table = np.array(JOINT_TABLE[dof, 1305 <= series < 8500])
        self.lower, self.upper = table[:, 0], table[:, 1]
        self.max_speed = self.model.velocity_limit[idx]  # 180 deg/s per joint (xArm specifications)
        self._joint_index = idx
        self.requested_host = host
        self.host = host or ""
        self.dof = dof
        self.report_period_s = report_period_s
        self.slow_reply_s = slow_reply_s
        self.servo_period_ns = int(servo_period_s * 1e9)
        self.max_tcp_speed_mm_s = max_tcp_speed_mm_s
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
        self._last_command_ns = 0
        self._slow_until = 0.0
        self._silenced: set = set()
        self._report_counter = 0
        self._ran: deque[tuple[int, int, np.ndarray]] = deque(maxlen=4)  # (arrival ns, cycle, target) that ran
        self._motions: deque[Motion] = deque()  # position-mode moves, the first one running
        self._ik = None
        self.commands: deque[ReceivedCommand] = deque(maxlen=200_000)  # servo targets taken
        self.arrivals: deque[Arrival] = deque(maxlen=200_000)  # every servo target that reached the box
        self.judged: deque[Judgement] = deque(maxlen=200_000)
        self.jolts = 0  # targets that ran past the acceleration or jerk limit
        self.superseded = 0  # targets replaced by a later one in the same servo cycle, never run
        self.requests: Counter[int] = Counter()  # register -> requests served
        self.unknown: Counter[int] = Counter()  # registers the emulator does not implement
        self.faults: list[tuple[int, str, int]] = []  # (monotonic ns, what, error code) for every latched error
        self.injected: list[tuple[int, str]] = []
        self._listeners: list[Listener] = []

    # ---- lifecycle ---------------------------------------------------------------------------------
    def start(self) -> XArmController:
        ports = (wire.COMMAND_PORT, wire.REPORT_NORMAL_PORT, wire.REPORT_RICH_PORT, wire.REPORT_REAL_PORT)
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
        for sock, port in zip(socks[1:], ports[1:]):
            self._listeners.append(Listener(sock, lambda c, port=port: self._serve_reports(c, port),
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
        self._advance(time.monotonic_ns())
        self.error = code
        self.state = wire.STOPPED
        self.speeds[:] = 0.0
        self._motions.clear()
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
            return struct.pack(">H", len(self._motions)), False
        if register == wire.GET_JOINT_POS:
            if not data:
                return wire.floats(self.angles, 7), False
            rows = (self.angles, self.speeds, np.zeros(self.dof))[:max(1, min(3, data[0] & 0x0F))]
            return b"".join(wire.floats(r, 7) for r in rows), False
        if register == wire.GET_TCP_POSE:
            return wire.floats(self.pose(), 6), False
        if register == wire.GET_TCP_POSE_AA:
            from teleprev.transforms import matrix_to_axis_angle

            flange = self._flange(self.angles)
            return wire.floats([*(flange[:3, 3] * 1000), *matrix_to_axis_angle(flange[:3, :3])], 6), False
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
            self._motions.clear()
            self._ran.clear()
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
            return b"", not self._move(register, data, now)
        self.unknown[register] += 1
        return b"", True

    def _set_state(self, wanted: int) -> bool:
        """Whether set_state(wanted) is refused (invalid)."""
        if wanted == 0:
            if self.error or not self.enabled:
                return True
            self.state = wire.MOVING if self._motions else wire.READY
            return False
        if wanted in (wire.STOPPED, wire.DECELERATION_STOP):  # both end with the arm stopped, its queue emptied
            self._motions.clear()
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

    # ---- kinematics --------------------------------------------------------------------------------
    def _flange(self, q: np.ndarray) -> np.ndarray:
        full = self.model.neutral()
        full[self._joint_index] = q
        return self.model.fk(full).matrix("link_eef")

    def pose(self) -> list[float]:
        """The TCP pose as the box reports it: x, y, z in mm, roll, pitch, yaw in rad."""
        flange = self._flange(self.angles)
        return [*(flange[:3, 3] * 1000.0), *rpy_from_matrix(flange[:3, :3])]

    # ---- position mode -----------------------------------------------------------------------------
    def _move(self, register: int, data: bytes, now: int) -> bool:
        """Queue a position-mode move; False when the box refuses it."""
        if not self._ready(wire.POSITION_MODE):
            return False
        start = self._motions[-1].goal if self._motions else self.angles
        if register == wire.MOVE_HOME and len(data) >= 12:
            speed = struct.unpack("<3f", data[:12])[0]
            goal = np.zeros(self.dof)
        elif register == wire.MOVE_JOINT and len(data) >= 40:
            values = struct.unpack("<10f", data[:40])
            goal, speed = np.array(values[:self.dof]), values[7]
        elif register == wire.MOVE_LINE and len(data) >= 36:
            values = struct.unpack("<9f", data[:36])
            goal = self._solve(values[:6], start)
            if goal is None:
                return False
            flange = self._flange(start)[:3, 3] * 1000.0
            distance_mm = float(np.linalg.norm(np.array(values[:3]) - flange))
            speed = 0.0 if values[6] <= 0 else values[6]
            duration = distance_mm / speed if speed > 0 else 0.0
            return self._queue(start, goal, duration, now)
        else:
            return False
        if np.any(goal < self.lower - 1e-6) or np.any(goal > self.upper + 1e-6):
            return False
        duration = float(np.max(np.abs(goal - start))) / speed if speed > 0 else 0.0
        return self._queue(start, goal, duration, now)

    def _queue(self, start: np.ndarray, goal: np.ndarray, duration: float, now: int) -> bool:
        self._motions.append(Motion(np.array(start, dtype=float), np.array(goal, dtype=float), max(duration, 0.0),
                                    now / 1e9 if not self._motions else 0.0))
        self.state = wire.MOVING
        return True

    def _solve(self, pose, q_start: np.ndarray) -> np.ndarray | None:
        """Joints for a TCP pose (mm, rad), by our IK; None where it does not reach."""
        from teleprev.robot.ik import ArmIK
        from teleprev.transforms import make_transform, rpy_to_matrix

        if self._ik is None:
            self._ik = ArmIK(self.model, "link_eef")
        target = make_transform(rpy_to_matrix(*pose[3:6]), np.array(pose[:3]) / 1000.0)
        full = self.model.neutral()
        full[self._joint_index] = q_start
        result = self._ik.solve(target, full[:len(self._ik.joint_names)])
        return np.asarray(result.q)[:self.dof] if result.converged else None

    def _advance(self, now_ns: int) -> None:
        """Bring the arm to `now`: position-mode moves along, a quiet servo stream back to READY."""
        now = now_ns / 1e9
        while self._motions:
            m = self._motions[0]
            if not m.began:
                m.began = now
            done = 1.0 if m.duration_s <= 0 else (now - m.began) / m.duration_s
            if done < 1.0:
                self.angles = m.start + (m.goal - m.start) * done
                self.speeds = (m.goal - m.start) / m.duration_s
                return
            self.angles = m.goal.copy()
            self._motions.popleft()
            if self._motions:
                self._motions[0].began = m.began + m.duration_s
            else:
                self.speeds[:] = 0.0
                if self.state == wire.MOVING:
                    self.state = wire.READY
        if self.state == wire.MOVING and self.mode == wire.SERVO_MODE and now_ns - self._last_command_ns > IDLE_AFTER_S * 1e9:
            self.state = wire.READY
            self.speeds[:] = 0.0

    # ---- servo mode --------------------------------------------------------------------------------
    def _servo(self, target: np.ndarray, now: int) -> None:
        """Take a servo target for this servo cycle (a later one in the same cycle replaces it), judged on
        arrival times against the target that ran before; one the arm must not follow faults it."""
        cycle = now // self.servo_period_ns
        if not self._ready(wire.SERVO_MODE):
            self.arrivals.append(Arrival(now, cycle, target, False))
            return
        outside = (target < self.lower - 1e-6) | (target > self.upper + 1e-6)
        if outside.any():
            j = int(np.argmax(outside))
            self.arrivals.append(Arrival(now, cycle, target, False))
            self._latch_locked(wire.JOINT_LIMIT, f"joint{j + 1} target {target[j]:.4f} outside "
                                                 f"[{self.lower[j]:.4f}, {self.upper[j]:.4f}]")
            return
        if self._ran and self._ran[-1][1] == cycle:  # only the latest target of a cycle runs
            self._ran.pop()
            self.superseded += 1
        if not self._ran or now - self._ran[-1][0] > STREAM_GAP_NS:  # a stream starts from the arm at rest
            self._ran.clear()
            self._ran.append((now - self.servo_period_ns, cycle - 1, self.angles.copy()))
        while len(self._ran) < 3:  # at rest before the stream's first target
            ns, k, q = self._ran[0]
            self._ran.appendleft((ns - self.servo_period_ns, k - 1, q))
        judged = self._judge(now, target)
        self.arrivals.append(Arrival(now, cycle, target, True))
        if judged is None:
            return
        self.commands.append(ReceivedCommand(now, target))
        self.judged.append(judged)
        last_ns, _, last = self._ran[-1]
        self.speeds = (target - last) / max((now - last_ns) / 1e9, self.servo_period_ns / 1e9)
        self._ran.append((now, cycle, target))
        self.angles = target
        self.state = wire.MOVING
        self._last_command_ns = now

    def _judge(self, now: int, target: np.ndarray) -> Judgement | None:
        """The target against the three that ran before it (divided differences on arrival times); None when
        it faults the arm (speed: error 24, flange speed: error 60)."""
        t = [(ns - now) / 1e9 for ns, _, _ in list(self._ran)[-3:]] + [0.0]
        q = [p for _, _, p in list(self._ran)[-3:]] + [target]
        dt = max(-t[2], self.servo_period_ns / 1e9)  # a target runs for at least one servo cycle
        speed = np.abs(q[3] - q[2]) / dt
        ratio = speed / self.max_speed
        if ratio.max() > 1.0 + SPEED_TOLERANCE:
            j = int(np.argmax(ratio))
            self._latch_locked(wire.SPEED_LIMIT, f"joint{j + 1} commanded at {speed[j]:.3g} rad/s "
                                                 f"(limit {self.max_speed[j]:g})")
            return None
        tcp_speed = float(np.linalg.norm(self._flange(q[3])[:3, 3] - self._flange(q[2])[:3, 3])) * 1000.0 / dt
        if tcp_speed > self.max_tcp_speed_mm_s * (1.0 + SPEED_TOLERANCE):
            self._latch_locked(wire.SERVO_TCP_SPEED, f"linear speed {tcp_speed:.0f} mm/s "
                                                     f"(limit {self.max_tcp_speed_mm_s:g} mm/s)")
            return None
        t[2] = -dt if t[2] > -dt else t[2]
        f1 = [(q[i + 1] - q[i]) / max(t[i + 1] - t[i], 1e-6) for i in range(3)]
        f2 = [(f1[i + 1] - f1[i]) / max(t[i + 2] - t[i], 1e-6) for i in range(2)]
        f3 = (f2[1] - f2[0]) / max(t[3] - t[0], 1e-6)
        accel = float(np.max(np.abs(2.0 * f2[1]))) / MAX_ACCELERATION
        jerk = float(np.max(np.abs(6.0 * f3))) / MAX_JERK
        if max(accel, jerk) > 1.0 + SPEED_TOLERANCE:
            self.jolts += 1
        return Judgement(now, float(ratio.max()), accel, jerk, tcp_speed)

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

    def report(self, size: int = wire.RICH_REPORT_SIZE) -> bytes:
        return wire.pack_report(self.report_state(), size)

    def _serve_reports(self, conn, port: int) -> None:
        listener = next(li for li in self._listeners if li.name.endswith(f"-{port}"))
        period = wire.REAL_REPORT_PERIOD_S if port == wire.REPORT_REAL_PORT else self.report_period_s
        next_t = time.monotonic()
        while not listener.stopped:
            with self._lock:
                silent = conn in self._silenced
            if not silent:
                if port == wire.REPORT_REAL_PORT:
                    conn.sendall(wire.pack_real_report(self.report_state()))
                else:
                    size = wire.NORMAL_REPORT_SIZE if port == wire.REPORT_NORMAL_PORT else wire.RICH_REPORT_SIZE
                    conn.sendall(self.report(size))
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
            if conn.fileno() < 0:
                return
