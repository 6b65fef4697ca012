"""Compiled (numba) kernels for the pipeline's element-wise per-step arithmetic: the hand's acceleration cap
with the target's velocity estimate, and the arm generator's arithmetic around ruckig.

Each kernel performs numpy's (or Python's float) operations on every element in the same order (no fused
multiply-add, no reassociation), with numpy's minimum / maximum on equal values (the second argument)
where the code they replace used those, so its results equal that code's bit for bit
(tests/pipeline/test_kernels.py); sessions recorded before them re-run identically. Scalars such as an
exponential's value are computed in Python and passed in (libm's exp and LLVM's may differ). Compiled on
the first call and cached on disk (cache=True); warm(), run by scripts/setup.sh, fills the cache.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit


class HandLimits(NamedTuple):
    """The hand limiter's caps, per joint (HandLimiter)."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    brake_fraction: float  # of the acceleration cap, for the braking envelope
    # the same envelope towards the joint limit ahead, whatever the target's velocity (formats up to 8: False)
    brakes_for_limits: bool


class ArmLimits(NamedTuple):
    """The arm generator's limits around ruckig, per joint (ArmGenerator)."""

    velocity: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    acceleration: np.ndarray


@njit(cache=True, inline="always")
def _max(a, b):
    return a if a > b else b  # np.maximum: the second argument on a tie (so -0 / +0 as numpy)


@njit(cache=True, inline="always")
def _min(a, b):
    return a if a < b else b


@njit(cache=True, inline="always")
def _track_joint(q, v, g, tv, dt, span, cap, lo, hi, a, brake_fraction, brakes_for_limits):
    """HandLimiter.track for one joint: (command, its velocity); g the target, tv its velocity (0.0: none)."""
    dv = a * 0.5 * span
    g = _min(_max(g, lo), hi)
    room = hi - g if tv > 0 else g - lo
    if tv * tv > a * room:
        tv = 0.0
    e = g - q
    ab = brake_fraction * a
    half = 0.5 * ab * dt
    brake = math.sqrt(2.0 * ab * abs(e) + half * half) - 0.5 * ab * dt
    step = e / dt
    want = _min(step, tv + brake) if e >= 0 else _max(step, tv - brake)
    if brakes_for_limits:
        # Met moving, a target short of a joint limit may be followed faster than the joint can stop before
        # the limit, where the command would be held (past the cap): the same envelope towards the limit.
        if want > 0:
            want = _min(want, math.sqrt(2.0 * ab * _max(hi - q, 0.0) + half * half) - half)
        elif want < 0:
            want = _max(want, half - math.sqrt(2.0 * ab * _max(q - lo, 0.0) + half * half))
    want = _min(_max(want, -cap), cap)
    w = _min(_max(want, v - dv), v + dv)
    bound = _max(cap, abs(v))
    w = _min(_max(w, -bound), bound)
    c = _min(_max(q + w * dt, lo), hi)
    return c, (c - q) / dt


@njit(cache=True, inline="always")
def _stop_joint(q, v, dt, span, lo, hi, a):
    """HandLimiter.stop for one joint: (command, its velocity)."""
    dv = a * 0.5 * span
    w = _max(v - dv, 0.0) if v > 0 else _min(v + dv, 0.0)
    c = _min(_max(q + w * dt, lo), hi)
    return c, (c - q) / dt


@njit(cache=True, inline="always")
def _span(dt, dt_before):
    return dt + (dt_before if dt_before > 0 else dt)


# How a step estimates its target's velocity (Motion's feed-forward): the estimate `hand_command` and
# `arm_plan` compute, from the target before (`before`, its estimate `before_v`) and this step's target.
ESTIMATE_NONE = 0  # no target velocity: plan to meet the target at rest
ESTIMATE_GIVEN = 1  # before_v as it is (arm_plan: the caller's target velocity; the target not moved on)
ESTIMATE_HELD = 2  # before_v as it is (arm_plan: the same wrist sample as last step)
ESTIMATE_ZERO = 3  # no usable target before: zero
ESTIMATE_RAW = 4  # (target - before) / gap, no estimate before
ESTIMATE_BLEND = 5  # keep * before_v + (1 - keep) * (target - before) / gap


@njit(cache=True, inline="always")
def _estimate(mode, target, before, before_v, gap, keep):
    """One joint of the target's velocity estimate (Motion._feedforward / _hand_feedforward's arithmetic)."""
    if mode == ESTIMATE_ZERO:
        return 0.0
    if mode == ESTIMATE_RAW:
        return (target - before) / gap
    if mode == ESTIMATE_BLEND:
        return keep * before_v + (1.0 - keep) * ((target - before) / gap)
    return before_v


@njit(cache=True)
def velocity_estimate(target, mode, before, before_v, gap, keep):
    """The target's velocity estimate (`mode`: ESTIMATE_ZERO, _RAW or _BLEND, over the gap in seconds),
    every joint: TargetEstimates' arithmetic, the same as the commands' estimates above."""
    out = np.empty(target.shape[0])
    for i in range(target.shape[0]):
        out[i] = _estimate(mode, target[i], before[i], before_v[i], gap, keep)
    return out


@njit(cache=True)
def hand_command(q, v, tracking, target, mode, before, before_v, keep, dt, dt_before, speed_frac, lower, upper,
                 velocity, acceleration, brake_fraction, brakes_for_limits):
    """Motion's hand step before the swept check, in one call: `tracking`, the target's velocity estimate
    (`mode`, over the gap dt) and HandLimiter.track towards `target` with it (ESTIMATE_NONE: no target
    velocity); else HandLimiter.stop. A dt <= 0 leaves q and v as they are. Arrays the mode does not read
    may be any of the right length.

    Returns (rows, unchanged): rows [command, its velocity, the estimate], unchanged: the command is q."""
    n = q.shape[0]
    out = np.empty((3, n))
    span = _span(dt, dt_before)
    unchanged = True
    for i in range(n):
        c, w, tv = q[i], v[i], 0.0
        if tracking:
            if mode != ESTIMATE_NONE:
                tv = _estimate(mode, target[i], before[i], before_v[i], dt, keep)
            if dt > 0:
                cap = velocity[i] * speed_frac
                clipped = _min(_max(tv, -0.9 * cap), 0.9 * cap) if mode != ESTIMATE_NONE else 0.0
                c, w = _track_joint(q[i], v[i], target[i], clipped, dt, span, cap, lower[i], upper[i],
                                    acceleration[i], brake_fraction, brakes_for_limits)
        elif dt > 0:
            c, w = _stop_joint(q[i], v[i], dt, span, lower[i], upper[i], acceleration[i])
        out[0, i] = c
        out[1, i] = w
        out[2, i] = tv
        if c != q[i]:
            unchanged = False
    return out, unchanged


@njit(cache=True)
def arm_plan(q, v, target, mode, before, before_v, gap, keep, ahead, dt, speed_frac, velocity, lower, upper,
             acceleration):
    """ArmGenerator's arithmetic before ruckig (track's limits on the target and its velocity, then _run's
    plan in the frame of the moving target), after the target's velocity estimate (`mode`; estimates made
    from wrist samples also move the target on by `ahead` seconds, as Motion._feedforward does). Python
    float arithmetic in the same order, so the same bits. Arrays the mode does not read may be any of
    the right length.

    Returns rows: ruckig's current velocity, max and min velocity and current position; the target within
    the limits and its velocity as planned (the frame, for arm_sample); the target moved on; the estimate."""
    n = q.shape[0]
    out = np.empty((8, n))
    for i in range(n):
        estimate = _estimate(mode, target[i], before[i], before_v[i], gap, keep) if mode != ESTIMATE_NONE else 0.0
        goal = target[i] + estimate * ahead if mode != ESTIMATE_NONE and mode != ESTIMATE_GIVEN else target[i]
        m = velocity[i] * speed_frac
        lo = lower[i]
        hi = upper[i]
        g = lo if goal < lo else hi if goal > hi else goal
        w = 0.0
        if mode != ESTIMATE_NONE:
            cap = 0.9 * m
            w = -cap if estimate < -cap else cap if estimate > cap else estimate
            room = hi - g if w > 0 else g - lo
            if w * w > acceleration[i] * room:  # no feed-forward towards a limit the joint could not stop before
                w = 0.0
        out[0, i] = v[i] - w
        out[1, i] = m - w
        out[2, i] = -m - w
        out[3, i] = q[i] - (g - w * dt)
        out[4, i] = g
        out[5, i] = w
        out[6, i] = goal
        out[7, i] = estimate
    return out


@njit(cache=True)
def arm_sample(base, base_v, sample, goal, lower, upper, tol, rest_velocity, rest_acceleration):
    """ArmGenerator's arithmetic after ruckig: `sample` (rows: position, velocity, acceleration in the plan's
    frame, which stands at `base` moving at `base_v`) back in joint space; then the position held within
    [lower, upper] as Motion does (numpy's minimum / maximum), whether it is within `tol` of `goal` on
    every joint, and JointMotion.at_rest's test.

    Returns (rows [position, velocity, acceleration, position held], held, close, at_rest)."""
    n = base.shape[0]
    out = np.empty((4, n))
    held = False
    close = True
    at_rest = True
    for i in range(n):
        q = base[i] + sample[0, i]
        v = base_v[i] + sample[1, i]
        a = sample[2, i]
        inside = _min(_max(q, lower[i]), upper[i])
        out[0, i] = q
        out[1, i] = v
        out[2, i] = a
        out[3, i] = inside
        if not inside == q:
            held = True
        if not abs(q - goal[i]) < tol:
            close = False
        if not (abs(v) < rest_velocity and abs(a) < rest_acceleration):
            at_rest = False
    return out, held, close, at_rest


@njit(cache=True)
def far_from_limits(q, v, a, lower, upper, acceleration, jerk):
    """Whether every joint is further from its limits than a bound on how far the hardest stop takes it
    (ArmGenerator.stops_inside: then that stop ends inside the limits, no ruckig needed). Towards the limit
    it heads for: its speed grown by what its acceleration adds while the jerk turns it round, held while
    it does, then braked at the acceleration limit. Back the other way, where its acceleration opposes its
    motion: the speed it reaches backwards while the jerk takes that acceleration away (a^2 / 2j - |v|),
    then the same. Each twice, and a millimetre radian, for margin."""
    for i in range(q.shape[0]):
        up = v[i] > 0 or (v[i] == 0 and a[i] > 0)
        speed = v[i] if up else -v[i]
        push = a[i] if up else -a[i]
        turn = (abs(a[i]) + acceleration[i]) / jerk[i]
        peak = speed + max(push, 0.0) ** 2 / (2.0 * jerk[i])
        ahead = upper[i] - q[i] if up else q[i] - lower[i]
        if ahead <= 2.0 * (peak * turn + peak * peak / (2.0 * acceleration[i])) + 1e-3:
            return False
        back = push * push / (2.0 * jerk[i]) - speed if push < 0 else 0.0
        if back > 0:
            behind = q[i] - lower[i] if up else upper[i] - q[i]
            if behind <= 2.0 * (back * turn + back * back / (2.0 * acceleration[i])) + 1e-3:
                return False
    return True


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "velocity_estimate": ("target", "mode", "before", "before_v", "gap", "keep"),
    "hand_command": ("q", "v", "tracking", "target", "mode", "before", "before_v", "keep", "dt", "dt_before",
                     "speed_frac", HandLimits),
    "arm_plan": ("q", "v", "target", "mode", "before", "before_v", "gap", "keep", "ahead", "dt", "speed_frac",
                 ArmLimits),
}
