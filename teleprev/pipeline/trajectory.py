"""Commands a real arm and hand can follow: an online jerk-limited generator for the arm, an
acceleration cap for the hand.

    arm   ruckig (time-optimal, jerk-limited, per-joint velocity/acceleration/jerk limits) from the last
          command's position, velocity and acceleration to the guarded target (and the target's own
          velocity, so a steady motion is tracked rather than chased), sampled at the next step's time.
    hand  per joint: the fastest velocity that still stops at the target, changed by at most the
          acceleration cap over the step.

Both are pure: the motion state (position, velocity, acceleration) goes in and comes out, and it lives in
PipelineState, so a re-run reproduces every command. The arm's commands are samples of one continuous
trajectory whose acceleration is continuous and whose jerk stays within the limit, so divided differences
on the command stamps stay within the limits too (by the mean value theorem for divided differences).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from teleprev.pipeline.kernels import hand_stop, hand_track, warm

REST_VELOCITY = 1e-6  # rad/s: below this (and no acceleration) a joint is at rest
REST_ACCELERATION = 1e-5
BRAKE_FRACTION = 0.8  # of the hand's acceleration cap, for the braking envelope


@dataclass(frozen=True)
class JointMotion:
    """Where the commands are: position, velocity and acceleration of each joint."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @classmethod
    def rest(cls, q: np.ndarray) -> "JointMotion":
        q = np.asarray(q, dtype=float)
        return cls(q, np.zeros_like(q), np.zeros_like(q))

    @cached_property  # asked several times per step; a JointMotion is never changed, only replaced
    def at_rest(self) -> bool:
        return bool((np.abs(self.v) < REST_VELOCITY).all() and (np.abs(self.a) < REST_ACCELERATION).all())


class ArmGenerator:
    """Online trajectory generation for the arm with ruckig. One instance per pipeline; every call sets
    every input, so no state carries over between calls (ruckig's own online cache is not used)."""

    def __init__(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                 jerk: np.ndarray):
        from ruckig import ControlInterface, InputParameter, Ruckig, Synchronization, Trajectory

        self.lower = np.asarray(lower, dtype=float)
        self.upper = np.asarray(upper, dtype=float)
        self.velocity = np.asarray(velocity, dtype=float)
        self.acceleration = np.asarray(acceleration, dtype=float)
        self.jerk = np.asarray(jerk, dtype=float)
        n = len(self.lower)
        self._otg = Ruckig(n)
        self._inp = InputParameter(n)
        self._traj = Trajectory(n)
        self._position, self._velocity_interface = ControlInterface.Position, ControlInterface.Velocity
        self._inp.max_acceleration = self.acceleration.tolist()
        self._inp.max_jerk = self.jerk.tolist()
        self._inp.target_position = [0.0] * n  # every target is planned in its own frame: at the origin, at rest
        self._inp.target_velocity = [0.0] * n
        self._inp.target_acceleration = [0.0] * n
        # Each joint on its own time-optimal profile: tracking a moving target, not a straight joint path.
        self._inp.synchronization = Synchronization.No
        self._zero = [0.0] * n
        self._lower, self._upper = self.lower.tolist(), self.upper.tolist()
        self._velocity, self._acceleration = self.velocity.tolist(), self.acceleration.tolist()

    def _run(self, s: JointMotion, dt: float, velocity: list[float], target: list[float] | None,
             target_v: list[float] | None) -> tuple[JointMotion, float] | None:
        """`dt` seconds along the time-optimal profile to `target`, moving at constant `target_v`, or (no
        target) to rest; and the profile's duration. A moving target is planned in its own frame (where
        it stands still, and the velocity limits shift by its velocity), so the profile meets it rather
        than the point where it was. Plain floats: per-element numpy calls would cost more than ruckig."""
        inp = self._inp
        tv = self._zero if target_v is None else target_v
        cv, vmax, vmin, cp, base = [], [], [], [], []
        for q, v, w, m, g in zip(s.q.tolist(), s.v.tolist(), tv, velocity, target if target is not None else tv):
            cv.append(v - w)
            vmax.append(m - w)
            vmin.append(-m - w)
            if target is None:
                base.append(q + w * dt)
            else:
                # `target` is where the target is dt from now; it was at target - tv * dt when s was.
                cp.append(q - (g - w * dt))
        inp.current_velocity = cv
        inp.current_acceleration = s.a.tolist()
        inp.max_velocity = vmax
        inp.min_velocity = vmin
        if target is None:
            inp.control_interface = self._velocity_interface
            inp.current_position = self._zero
        else:
            inp.control_interface = self._position
            inp.current_position = cp
            base = target
        if self._otg.calculate(inp, self._traj).value < 0:  # an error result: invalid input or no solution
            return None
        q, v, a = self._traj.at_time(dt if dt > 0.0 else 0.0)
        return (JointMotion(np.array([b + x for b, x in zip(base, q)]), np.array([w + x for w, x in zip(tv, v)]), np.array(a)),
                self._traj.duration)

    def track(self, s: JointMotion, target: np.ndarray, target_v: np.ndarray | None, dt: float,
              speed_frac: float = 1.0) -> tuple[JointMotion, bool]:
        """The motion `dt` seconds on, heading for `target` (met moving at `target_v`, or at rest), and
        whether it gets there within those `dt` seconds."""
        velocity = self._velocity if speed_frac == 1.0 else [m * speed_frac for m in self._velocity]
        target = [lo if g < lo else hi if g > hi else g for g, lo, hi in zip(target.tolist(), self._lower, self._upper)]
        tv = None
        if target_v is not None:
            tv = []
            for w, g, m, lo, hi, acc in zip(target_v.tolist(), target, velocity, self._lower, self._upper, self._acceleration):
                cap = 0.9 * m
                w = -cap if w < -cap else cap if w > cap else w
                # No feed-forward towards a joint limit the joint could not stop before.
                room = hi - g if w > 0 else g - lo
                tv.append(0.0 if w * w > acc * room else w)
        out = self._run(s, dt, velocity, target, tv)
        if out is None:
            return self.stop(s, dt), False
        return out[0], out[1] <= dt

    def stop(self, s: JointMotion, dt: float) -> JointMotion:
        """A controlled stop: velocity and acceleration brought to zero within the limits."""
        out = self._run(s, dt, np.maximum(self.velocity, np.abs(s.v)).tolist(), None, None)
        if out is None:  # cannot happen with positive limits; hold rather than guess
            return JointMotion.rest(s.q)
        out = out[0]
        if out.at_rest:
            return JointMotion.rest(out.q)
        return out


class HandLimiter:
    """Acceleration-capped position commands, joint by joint (a Dynamixel in position mode follows these).

    The velocity between two commands changes by at most acceleration x (the mean of the last two step
    intervals), which is what the divided difference on the command stamps measures.
    """

    def __init__(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray):
        self.lower = _vector(lower)
        self.upper = _vector(upper)
        self.velocity = _vector(velocity)
        self.acceleration = _vector(acceleration)
        warm()  # load the kernels from numba's cache now, not in a live loop's first steps

    def track(self, q: np.ndarray, v: np.ndarray, target: np.ndarray, target_v: np.ndarray | None, dt: float,
              dt_before: float, speed_frac: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(command, its velocity) one step of dt towards `target` (where the target is at the end of the
        step, moving at `target_v`) from command q moving at v.

        Per joint (compiled: kernels.hand_track): the target clamped to the limits and its velocity to 0.9
        of the cap, dropped where the target is about to stop at a joint limit; then land on the target at
        the end of the step, unless that closes in faster than, in the target's frame, steps of dt each
        slowing by a*dt could still stop within the distance (braking planned at BRAKE_FRACTION of the cap
        leaves room to land exactly); the velocity changes by at most the cap over the step."""
        if dt <= 0:
            return q, v
        has_tv = target_v is not None
        return hand_track(_vector(q), _vector(v), _vector(target), _vector(target_v) if has_tv else self.lower, has_tv,
                          float(dt), float(dt_before), float(speed_frac), self.lower, self.upper, self.velocity,
                          self.acceleration, BRAKE_FRACTION)

    def stop(self, q: np.ndarray, v: np.ndarray, dt: float, dt_before: float) -> tuple[np.ndarray, np.ndarray]:
        """One step of the hardest braking the cap allows (compiled: kernels.hand_stop)."""
        if dt <= 0:
            return q, v
        return hand_stop(_vector(q), _vector(v), float(dt), float(dt_before), self.lower, self.upper, self.acceleration)


def _vector(x) -> np.ndarray:
    return np.ascontiguousarray(x, dtype=np.float64)
