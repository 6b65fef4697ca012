"""What the real actuators (xarm.arm, leap.hand) share: state polled over a request/reply link, and
every command checked again before it leaves the host.

The pipeline's command guard already keeps commands inside the joint limits; JointLimits is the second
line (defense in depth): a command that names unknown joints, has a non-finite value or lies outside
the URDF's limits is refused with a DeviceError, counted, and never sent.

A write that fails (the controller refused the command, the link broke) or a command the device must not
follow (`_refuse` raising DeviceFault) stops the device's commands: every later send() raises, and the
next read() raises the fault, so the runner records an `error` event (the session goes back to preview)
and reconnects; connecting again clears it, and the device then says what it needs first.
"""

from __future__ import annotations

import threading
import time
from abc import abstractmethod
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from teleprev.devices.contract import Actuator, DeviceContext, StreamSpec
from teleprev.devices.pacing import wait_until_due
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample, Sample

_TOLERANCE = 1e-9  # rad: round-off of a command computed exactly at a limit
COMMAND_TURN_S = 0.1  # the longest a poll gives the lock up between two tries, for a waiting command


@dataclass
class JointLimits:
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def from_urdf(cls, robot: str, names: tuple[str, ...], where: str) -> JointLimits:
        from teleprev.robot.model import load_robot

        model = load_robot(robot)
        missing = [n for n in names if n not in model.joint_index]
        if missing:
            raise ConfigError(f"robot {model.name!r} has no joints {', '.join(missing)} "
                              f"(its joints: {', '.join(model.joint_names)})", where)
        idx = model.indices(names)
        return cls(names, model.lower[idx].copy(), model.upper[idx].copy())

    def target(self, command: JointSample, previous: np.ndarray, where: str) -> np.ndarray:
        """The full joint vector the command asks for (joints it leaves out keep `previous`), or a
        DeviceError saying why it is refused."""
        index = {n: i for i, n in enumerate(self.names)}
        unknown = [n for n in command.names if n not in index]
        if unknown:
            raise DeviceError(f"command refused: unknown joints {unknown} (expected {', '.join(self.names)})", where)
        positions = np.asarray(command.positions, dtype=float)
        if positions.shape != (len(command.names),):
            raise DeviceError(f"command refused: {positions.shape} positions for {len(command.names)} names", where)
        if not np.all(np.isfinite(positions)):
            bad = [n for n, v in zip(command.names, positions) if not np.isfinite(v)]
            raise DeviceError(f"command refused: non-finite positions for {', '.join(bad)}", where)
        target = np.array(previous, dtype=float)
        target[[index[n] for n in command.names]] = positions
        outside = (target < self.lower - _TOLERANCE) | (target > self.upper + _TOLERANCE)
        if outside.any():
            detail = "; ".join(f"{n}={v:.4f} not in [{lo:.4f}, {hi:.4f}]" for n, v, lo, hi, o in
                               zip(self.names, target, self.lower, self.upper, outside) if o)
            raise DeviceError(f"command refused: outside the joint limits: {detail}", where)
        return target


class DeviceFault(DeviceError):
    """Raised by `_refuse` for a command the device must not follow at all (not just this once): it stops
    the device's commands until it is reconnected."""


class PolledSettings(Protocol):
    rate_hz: float  # how often the state is polled


P = TypeVar("P", bound=PolledSettings)


class PolledActuator(Actuator[P]):
    """An actuator whose `joints` (joints of the URDF `robot`, which gives their limits) are polled at
    `settings.rate_hz` on /<kind>/<name>/state and whose commands are checked twice.

    Subclasses implement the five calls below, which run under the actuator's lock, and may refuse more
    than the limits do in `_refuse(target)`.
    """

    def __init__(self, name: str, settings: P, context: DeviceContext, robot: str, joints: tuple[str, ...],
                 where: str):
        super().__init__(name, settings, context)
        self.limits = JointLimits.from_urdf(robot, joints, f"[devices.{name}]")
        self.joint_names = joints
        self.where = where  # names the device in errors, e.g. "device 'arm' (xArm 192.168.1.185)"
        self.state_topic = self.topic("state")
        self.period_ns = int(round(1e9 / settings.rate_hz))
        self._lock = threading.Lock()
        self._command_waiting = threading.Event()  # send() wants the lock (_let_commands_through)
        self._connected = False
        self._target: np.ndarray | None = None
        self._refused = 0
        self._next_ns = 0
        self._fault: DeviceError | None = None  # what stopped the commands, until the next connect

    @abstractmethod
    def _open(self) -> None:
        """Open the link (DeviceError if it cannot be opened)."""

    @abstractmethod
    def _start(self) -> np.ndarray:
        """Make the open device ready for commands; its joint positions then."""

    @abstractmethod
    def _close(self) -> None:
        """Close the link."""

    @abstractmethod
    def _poll(self) -> np.ndarray:
        """The joint positions now."""

    @abstractmethod
    def _write(self, target: np.ndarray) -> None:
        """Send a full target that passed every check."""

    def _refuse(self, target: np.ndarray, stamp_ns: int) -> None:
        """Raise DeviceError to refuse a target the limits allow (default: refuse nothing more), DeviceFault
        to also stop the commands. `stamp_ns` is the instant the command is meant for."""

    def _let_commands_through(self) -> None:
        """From inside `_poll` (the lock held): give the lock up until a command waiting for it has been
        written (COMMAND_TURN_S at most), so that a read's retries do not hold back the commands."""
        self._lock.release()
        try:
            deadline = time.monotonic() + COMMAND_TURN_S
            while self._command_waiting.is_set() and time.monotonic() < deadline:
                time.sleep(0.0002)
        finally:
            self._lock.acquire()

    def connect(self) -> None:
        with self._lock:
            self._open()
            try:
                q = self._start()
            except DeviceError:
                self._close()
                raise
            self._target = np.clip(q, self.limits.lower, self.limits.upper)  # the first command is checked against it
            self._fault = None
            self._connected = True
            self._next_ns = self.context.clock.now_ns()

    def disconnect(self) -> None:
        with self._lock:
            was, self._connected = self._connected, False
            if was:
                self._close()

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.state_topic, "joints", self.settings.rate_hz)]

    def counters(self) -> dict[str, int]:
        return {"refused_commands": self._refused}

    def read(self, timeout_s: float) -> list[Sample]:
        clock = self.context.clock
        if not wait_until_due(clock, self._next_ns, timeout_s):
            return []
        with self._lock:
            if not self._connected:
                raise DeviceError("not connected", self.where)
            if self._fault is not None:
                raise self._fault
            before = clock.now_ns()
            q = self._poll()
            after = clock.now_ns()
        self._next_ns = max(self._next_ns + self.period_ns, after)
        # The device sampled somewhere between request and reply: take the middle.
        return [Sample(self.state_topic, JointSample((before + after) // 2, self.joint_names, q))]

    def send(self, command: JointSample) -> None:
        self._command_waiting.set()
        with self._lock:
            self._command_waiting.clear()
            if not self._connected:
                raise DeviceError("not connected: command dropped", self.where)
            if self._fault is not None:
                raise DeviceError(f"command dropped: the commands stopped after a fault ({self._fault.message})",
                                  self.where)
            try:
                target = self.limits.target(command, self._target, self.where)
                self._refuse(target, command.stamp_ns)
            except DeviceFault as fault:
                self._refused += 1
                self._fault = fault
                raise
            except DeviceError:
                self._refused += 1
                raise
            try:
                self._write(target)
            except DeviceError as fault:
                self._fault = fault
                raise
            self._target = target
