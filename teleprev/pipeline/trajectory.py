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

from teleprev.kernels.motion import (
    ESTIMATE_GIVEN,
    ESTIMATE_NONE,
    ArmLimits,
    HandLimits,
    arm_plan,
    arm_sample,
    far_from_limits,
    hand_command,
)

REST_VELOCITY = 1e-6  # rad/s: below this (and no acceleration) a joint is at rest
REST_ACCELERATION = 1e-5
BRAKE_FRACTION = 0.8  # of the hand's acceleration cap, for the braking envelope
PLAN_GOAL, PLAN_ESTIMATE = 6, 7  # rows of ArmGenerator.plan: the target moved on, its velocity estimate


@dataclass(frozen=True)
class JointMotion:
    """Where the commands are: position, velocity and acceleration of each joint."""

    q: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @classmethod
    def rest(cls, q: np.ndarray) -> JointMotion:
        q = np.asarray(q, dtype=float)
        return cls(q, np.zeros_like(q), np.zeros_like(q))

    @classmethod
    def known(cls, q: np.ndarray, v: np.ndarray, a: np.ndarray, at_rest: bool) -> JointMotion:
        """A JointMotion whose at_rest the caller has computed already (kernels.arm_sample). Built as
        frozen.evolve builds copies (a frozen dataclass's __init__ costs about a microsecond)."""
        s = object.__new__(cls)
        s.__dict__.update(q=q, v=v, a=a, at_rest=at_rest)  # at_rest: where cached_property keeps its value
        return s

    @cached_property  # asked several times per step; a JointMotion is never changed, only replaced
    def at_rest(self) -> bool:
        return bool((np.abs(self.v) < REST_VELOCITY).all() and (np.abs(self.a) < REST_ACCELERATION).all())


class ArmGenerator:
    """Online trajectory generation for the arm with ruckig. One instance per pipeline; every call sets
    every input, so no state carries over between calls (ruckig's own online cache is not used)."""

    def __init__(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray,
                 jerk: np.ndarray):
        from ruckig import ControlInterface, InputParameter, Ruckig, Synchronization, Trajectory

        self.lower = float_vector(lower)  # the kernels' argument type: contiguous float64
        self.upper = float_vector(upper)
        self.velocity = float_vector(velocity)
        self.acceleration = float_vector(acceleration)
        self.jerk = float_vector(jerk)
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
        self._limits = ArmLimits(self.velocity, self.lower, self.upper, self.acceleration)
        # load the kernels from numba's cache now, not in a live loop's first steps
        self.follow(JointMotion.rest(self.lower), self.plan(JointMotion.rest(self.lower), self.upper, 0.01), 0.01)

    def plan(self, s: JointMotion, target: np.ndarray, dt: float, speed_frac: float = 1.0,
             estimate: int = ESTIMATE_NONE, before: np.ndarray | None = None, before_v: np.ndarray | None = None,
             gap: float = 0.0, keep: float = 0.0, ahead: float = 0.0,
             velocity: np.ndarray | None = None) -> np.ndarray:
        """ruckig's inputs for `dt` seconds towards `target` (kernels.arm_plan's rows), with the target's velocity
        estimated as `estimate` says from the target before and its estimate (see kernels.ESTIMATE_*).

        The target is clamped to the limits and its velocity to 0.9 of the cap, dropped towards a joint limit
        the joint could not stop before. A moving target is planned in its own frame (where it stands still,
        and the velocity limits shift by its velocity), so the profile meets it rather than the point where
        it was: `target` is where the target is dt from now, and it was at target - velocity * dt when s was.
        `velocity`: the joints' velocity limits for this plan, below their caps (default: the caps)."""
        target = float_vector(target)
        limits = self._limits if velocity is None else self._limits._replace(velocity=float_vector(velocity))
        return arm_plan(float_vector(s.q), float_vector(s.v), target, estimate,
                        target if before is None else float_vector(before),
                        target if before_v is None else float_vector(before_v), float(gap), float(keep), float(ahead),
                        float(dt), float(speed_frac), *limits)

    def follow(self, s: JointMotion, plan: np.ndarray, dt: float, tol: float = 0.0,
               jerk_frac: float = 1.0) -> tuple | None:
        """`dt` seconds along the time-optimal profile of `plan` (ArmGenerator.plan's rows), or None where ruckig
        finds none. Returns (the motion, whether the profile reaches the target within dt, its position held
        within the joint limits, whether that hold changed it, whether it is within `tol` of the target).
        `jerk_frac`: the profile at that fraction of the jerk limit."""
        inp = self._inp
        inp.current_velocity, inp.max_velocity, inp.min_velocity, inp.current_position = plan[:4].tolist()
        inp.current_acceleration = s.a.tolist()
        inp.control_interface = self._position
        if jerk_frac != 1.0:
            inp.max_jerk = (self.jerk * jerk_frac).tolist()
        try:
            solved = self._otg.calculate(inp, self._traj).value >= 0  # else invalid input or no solution
        finally:
            if jerk_frac != 1.0:
                inp.max_jerk = self.jerk.tolist()
        if not solved:
            return None
        sample = np.array(self._traj.at_time(dt if dt > 0.0 else 0.0))
        rows, held, close, at_rest = arm_sample(plan[4], plan[5], sample, plan[6], self.lower, self.upper, tol,
                                                REST_VELOCITY, REST_ACCELERATION)
        motion = JointMotion.known(rows[0], rows[1], rows[2], at_rest)
        return motion, self._traj.duration <= dt, rows[3] if held else rows[0], held, close

    def track(self, s: JointMotion, target: np.ndarray, target_v: np.ndarray | None, dt: float,
              speed_frac: float = 1.0) -> tuple[JointMotion, bool]:
        """The motion `dt` seconds on, heading for `target` (met moving at `target_v`, or at rest), and
        whether it gets there within those `dt` seconds."""
        estimate = ESTIMATE_NONE if target_v is None else ESTIMATE_GIVEN
        out = self.follow(s, self.plan(s, target, dt, speed_frac, estimate, before_v=target_v), dt)
        if out is None:
            return self.stop(s, dt), False
        return out[0], out[1]

    def _plan_stop(self, s: JointMotion) -> bool:
        """ruckig's hardest stop from s (velocity and acceleration to zero within the limits) into the
        trajectory, in the frame where s stands at the origin; False where it finds none (which positive
        limits never give)."""
        inp = self._inp
        velocity = np.maximum(self.velocity, np.abs(s.v)).tolist()
        inp.current_velocity = s.v.tolist()
        inp.current_acceleration = s.a.tolist()
        inp.max_velocity = velocity
        inp.min_velocity = [-m for m in velocity]
        inp.control_interface = self._velocity_interface
        inp.current_position = self._zero
        return self._otg.calculate(inp, self._traj).value >= 0

    def track_inside(self, s: JointMotion, target: np.ndarray, target_v: np.ndarray | None, dt: float,
                     speed_frac: float = 1.0) -> JointMotion:
        """track's motion, except that where it would leave less room than the hardest stop needs before a
        joint limit it brakes instead, as the live planner does: a followed stream never passes a limit."""
        estimate = ESTIMATE_NONE if target_v is None else ESTIMATE_GIVEN
        out = self.follow(s, self.plan(s, target, dt, speed_frac, estimate, before_v=target_v), dt)
        if out is None or out[3] or not self.stops_inside(out[0]):
            return self.brake(s, dt)[0]
        return out[0]

    def stops_inside(self, m: JointMotion) -> bool:
        """Whether braking as hard as the limits allow from m ends inside every joint limit. The exact stop
        (ruckig) is computed only where a joint is closer to a limit than a bound on its braking distance
        (kernels.far_from_limits)."""
        q, v, a = float_vector(m.q), float_vector(m.v), float_vector(m.a)
        if far_from_limits(q, v, a, self.lower, self.upper, self.acceleration, self.jerk):
            return True
        end = self.stop_position(m)
        return bool(((end >= self.lower) & (end <= self.upper)).all())

    def brake(self, m: JointMotion, dt: float) -> tuple[JointMotion, bool]:
        """The hardest stop the limits allow, dt on, and whether a joint had to be held at its limit as a last
        resort (never needed while every motion taken stops inside them)."""
        out = self.stop(m, dt)
        inside = np.minimum(np.maximum(out.q, self.lower), self.upper)
        held = inside != out.q
        if not held.any():
            return out, False
        # Only the joints at a limit are held there: the others go on braking. Holding the whole arm at
        # once took every other joint's braking velocity to zero in one tick (89 rad/s^2 on joint4, seen).
        out = JointMotion(inside, np.where(held, 0.0, out.v), np.where(held, 0.0, out.a))
        return (JointMotion.rest(inside) if out.at_rest else out), True

    def stop_position(self, s: JointMotion) -> np.ndarray:
        """Where the hardest stop the limits allow (stop's profile) comes to rest from s."""
        if not self._plan_stop(s):
            return s.q
        return s.q + np.array(self._traj.at_time(self._traj.duration)[0])

    def stop_time_bound(self) -> float:
        """Seconds the hardest stop takes at most, from any state the commands can be in (speed up to the
        cap, accelerating as hard as allowed): the jerk turns the acceleration round (2 a/j, the speed
        growing by a^2/2j meanwhile), the speed is braked at the acceleration limit, the jerk brings the
        acceleration back to zero (a/j). The slowest joint's."""
        a, j = self.acceleration, self.jerk
        return float((3.0 * a / j + (self.velocity + a * a / (2.0 * j)) / a).max())

    def stop(self, s: JointMotion, dt: float) -> JointMotion:
        """A controlled stop: velocity and acceleration brought to zero within the limits."""
        if not self._plan_stop(s):  # cannot happen with positive limits; hold rather than guess
            return JointMotion.rest(s.q)
        p, w, a = self._traj.at_time(dt if dt > 0.0 else 0.0)
        # The frame of a target at rest, as in plan: "+ 0.0" turns -0.0 into 0.0, which the recorded commands did.
        q = [x + 0.0 * dt + y for x, y in zip(s.q.tolist(), p)]
        out = JointMotion(np.array(q), np.array([0.0 + y for y in w]), np.array(a))
        if out.at_rest:
            return JointMotion.rest(out.q)
        return out


class HandLimiter:
    """Acceleration-capped position commands, joint by joint (a Dynamixel in position mode follows these).

    The velocity between two commands changes by at most acceleration x (the mean of the last two step
    intervals), which is what the divided difference on the command stamps measures.
    """

    brakes_for_limits = True  # the braking envelope towards the joint limit ahead too (formats up to 8: False)

    def __init__(self, lower: np.ndarray, upper: np.ndarray, velocity: np.ndarray, acceleration: np.ndarray):
        self.lower = float_vector(lower)
        self.upper = float_vector(upper)
        self.velocity = float_vector(velocity)
        self.acceleration = float_vector(acceleration)
        self._limits = HandLimits(self.lower, self.upper, self.velocity, self.acceleration, BRAKE_FRACTION,
                                  self.brakes_for_limits)
        q = self.lower  # load the kernel from numba's cache now, not in a live loop's first steps
        self.command(q, q, q, ESTIMATE_NONE, None, None, 0.0, 0.01, 0.01)

    def track(self, q: np.ndarray, v: np.ndarray, target: np.ndarray, target_v: np.ndarray | None, dt: float,
              dt_before: float, speed_frac: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """(command, its velocity) one step of dt towards `target` (where the target is at the end of the
        step, moving at `target_v`) from command q moving at v.

        Per joint (compiled: kernels.hand_command): the target clamped to the limits and its velocity to 0.9
        of the cap, dropped where the target is about to stop at a joint limit; then land on the target at
        the end of the step, unless that closes in faster than, in the target's frame, steps of dt each
        slowing by a*dt could still stop within the distance (braking planned at BRAKE_FRACTION of the cap
        leaves room to land exactly), or (brakes_for_limits) than such steps could stop before the joint
        limit ahead; the velocity changes by at most the cap over the step."""
        if dt <= 0:
            return q, v
        estimate = ESTIMATE_NONE if target_v is None else ESTIMATE_GIVEN
        rows, _ = self.command(q, v, target, estimate, None, target_v, 0.0, dt, dt_before, speed_frac)
        return rows[0], rows[1]

    def stop_time_bound(self) -> float:
        """Seconds braking takes at most from the speed cap, at the braking envelope's share of the
        acceleration cap (the hardest stop uses all of it). The slowest joint's."""
        return float((self.velocity / (BRAKE_FRACTION * self.acceleration)).max())

    def stop(self, q: np.ndarray, v: np.ndarray, dt: float, dt_before: float) -> tuple[np.ndarray, np.ndarray]:
        """One step of the hardest braking the cap allows (compiled: kernels.hand_command, not tracking)."""
        if dt <= 0:
            return q, v
        rows, _ = self.command(q, v, None, ESTIMATE_NONE, None, None, 0.0, dt, dt_before)
        return rows[0], rows[1]

    def stop_straight(self, q: np.ndarray, v: np.ndarray, dt: float,
                      dt_before: float) -> tuple[np.ndarray, np.ndarray]:
        """One step of braking that keeps the direction of v: every joint's velocity scaled down by the same
        factor, as far as the cap lets the joint that needs it most (so the commands stay on the straight line
        along v, where stop's per-joint braking bends away from it when the joints move at different speeds)."""
        if dt <= 0:
            return q, v
        span = dt + (dt_before if dt_before > 0 else dt)
        moving = v != 0
        if not moving.any():
            return q, v
        keep = max(0.0, float(np.max(1.0 - self.acceleration[moving] * 0.5 * span / np.abs(v[moving]))))
        c = np.minimum(np.maximum(q + (keep * v) * dt, self.lower), self.upper)
        return c, (c - q) / dt

    def command(self, q: np.ndarray, v: np.ndarray, target: np.ndarray | None, estimate: int,
                before: np.ndarray | None, before_v: np.ndarray | None, keep: float, dt: float, dt_before: float,
                speed_frac: float = 1.0) -> tuple[np.ndarray, bool]:
        """track towards `target` with its velocity estimated as `estimate` says from the target before and
        its estimate (kernels.ESTIMATE_*, over the gap dt; ESTIMATE_NONE: no target velocity), or (no target)
        stop, in one kernel call (kernels.hand_command). Returns (rows: command, its velocity, the estimate;
        whether the command is q)."""
        q = float_vector(q)
        tracking = target is not None
        return hand_command(q, float_vector(v), tracking, float_vector(target) if tracking else q, estimate,
                            q if before is None else float_vector(before),
                            q if before_v is None else float_vector(before_v),
                            float(keep), float(dt), float(dt_before), float(speed_frac), *self._limits)


def float_vector(x) -> np.ndarray:
    """x as the kernels take it: a contiguous float64 array (x itself when it is one)."""
    return np.ascontiguousarray(x, dtype=np.float64)
