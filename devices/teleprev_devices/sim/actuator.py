"""What the sim arm and hand share: joints that follow position commands and report their state.

Kinematic (the default): the joints follow the latest command exactly, within their speed limits. On a
physics rig (DeviceContext.physics) each command becomes the drives' targets in the physics world at once
and the state is what the world measures: the world steps in its own process and the targets and state
pass through shared memory, so `send` works the same from the session process or the paced sender's.
"""

from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from teleprev.devices import Actuator, DeviceContext, DeviceError, JointSample
from teleprev_devices.sim.device import SimDevice, TimingSettings
from teleprev_devices.sim.follow import JointFollower
from teleprev_devices.sim.world import shared_world


@dataclass
class ActuatorSettings(TimingSettings):
    home: tuple[float, ...] = ()  # starting positions, one per joint
    max_velocity: float = 0.0  # for every joint; 0: the URDF's velocity limits


A = TypeVar("A", bound=ActuatorSettings)


class SimActuator(SimDevice[A], Actuator[A], stream="state", payload="joints"):
    """Joint state on /<kind>/<name>/state. Subclasses set, in __init__ after this one: joint_names,
    lower, upper and max_velocity (`use_urdf_joints` sets all four), home and max_acceleration. A command
    takes effect from the first state step at or after its stamp (the instant it was sent)."""

    def __init__(self, name: str, settings: A, context: DeviceContext):
        super().__init__(name, settings, context)
        self.world = shared_world(context)
        self.physics = context.physics  # None: kinematic
        self.link = None  # the physics world's joints, once connected
        self.max_acceleration: float = np.inf
        self._commands: deque[tuple[int, np.ndarray]] = deque(maxlen=1000)
        self._lock = threading.Lock()

    def check_home(self, home: np.ndarray) -> np.ndarray:
        if len(home) != len(self.joint_names):
            raise self.bad_setting("home", f"needs {len(self.joint_names)} values ({', '.join(self.joint_names)}), "
                                           f"got {len(home)}")
        outside = [f"{n}={v:g} not in [{lo:g}, {hi:g}]"
                   for n, v, lo, hi in zip(self.joint_names, home, self.lower, self.upper) if not lo <= v <= hi]
        if outside:
            raise self.bad_setting("home", "outside the joint limits: " + "; ".join(outside))
        return np.asarray(home, dtype=float)

    def use_urdf_joints(self, names: tuple[str, ...]) -> None:
        """These joints of the robot model, with its limits; speed capped by the `max_velocity` setting
        where it is given (never above the URDF's limit)."""
        model = self.world.model
        idx = model.indices(names)
        self.joint_names = names
        self.lower, self.upper = model.lower[idx], model.upper[idx]
        self.max_velocity = urdf_velocity = model.velocity_limit[idx]
        setting = self.settings.max_velocity
        if setting > 0:
            if np.any(setting > urdf_velocity):
                raise self.bad_setting(
                    "max_velocity", f"{setting:g} is above the URDF's limit ({urdf_velocity.min():g})"
                )
            self.max_velocity = np.full_like(urdf_velocity, setting)

    def _open(self) -> None:
        # A reconnect finds the joints where they were (a real arm or hand does not jump home).
        start = self.follower.q if getattr(self, "follower", None) is not None else self.home
        self.follower = JointFollower(start, self.lower, self.upper, self.max_velocity, self.max_acceleration)
        self._index = {n: i for i, n in enumerate(self.joint_names)}
        self._stepped_ns: int | None = None
        with self._lock:
            self._commands.clear()
        if self.physics is not None:
            first = self.link is None
            self.link = self.physics.link()
            if first:  # the world's robot starts where this device's home is
                self.physics.place_robot(dict(zip(self.joint_names, self.home)))
            return
        self.world.set_joints(self.joint_names, self.state_positions())

    def send(self, command: JointSample) -> None:
        where = f"device {self.name!r}"
        unknown = [n for n in command.names if n not in self.joint_names]
        if unknown:
            raise DeviceError(f"command names unknown joints {unknown} (expected {', '.join(self.joint_names)})", where)
        positions = np.asarray(command.positions, dtype=float)
        if positions.shape != (len(command.names),) or not np.all(np.isfinite(positions)):
            raise DeviceError("command positions must be finite, one per name", where)
        if not self._connected:
            raise DeviceError("not connected", where)
        with self._lock:
            target = (self._commands[-1][1] if self._commands else self.follower.target).copy()
            target[[self._index[n] for n in command.names]] = positions
            refused = self._refuse(command.stamp_ns, target)
            if not refused:
                # servo mode runs a command from the instant it was sent (its stamp), however late it arrived
                self._commands.append((command.stamp_ns, target))
                if self.link is not None:  # physics: the drives' targets from now on
                    self.link.set_targets(dict(zip(self.joint_names, target.tolist())))
        if refused:
            self._refused(refused)

    def _refuse(self, stamp_ns: int, target: np.ndarray) -> str:
        """Why the controller refuses this target ("": it runs it). Called with the commands' lock held."""
        return ""

    def _refused(self, why: str) -> None:
        """The controller refused a target (`_refuse`): what it does then."""

    def measured(self) -> tuple[np.ndarray, np.ndarray]:
        """The joints' positions and velocities now."""
        if self.link is not None:
            _, q, v = self.link.joint_state(self.joint_names)
            return q, v
        return self.follower.q, self.follower.v

    def hold_here(self) -> None:
        """Stop where the joints are (a controller fault): no target beyond the current positions."""
        with self._lock:
            self._commands.clear()
        q, _ = self.measured()
        self.follower.set_target(self.follower.q)
        self.follower.v[:] = 0.0
        if self.link is not None:
            self.link.set_targets(dict(zip(self.joint_names, q.tolist())))

    def _advance(self, true_ns: int) -> None:
        """Integrate up to true_ns in steps of the state period, each with the latest command sent by then."""
        if self._stepped_ns is None:
            self._stepped_ns = true_ns
            return
        dt = self.period_ns / 1e9
        steps = max(0, int(round((true_ns - self._stepped_ns) / self.period_ns)))
        for k in range(1, steps + 1):
            t = self._stepped_ns + k * self.period_ns
            with self._lock:
                while self._commands and self._commands[0][0] <= t:
                    self.follower.set_target(self._commands.popleft()[1])
            self.follower.step(dt)
        self._stepped_ns = true_ns

    def state_positions(self) -> np.ndarray:
        return self.follower.q.copy()

    def state_velocities(self) -> np.ndarray:
        return self.follower.v.copy()

    def _acquire(self, true_ns: int) -> JointSample:
        if self.link is not None:
            self.world.follow_operator(self.physics, true_ns)
            q, v = self.measured()
            return JointSample(0, self.joint_names, q, v)
        self._advance(true_ns)
        q = self.state_positions()
        self.world.set_joints(self.joint_names, q)
        return JointSample(0, self.joint_names, q, self.state_velocities())
