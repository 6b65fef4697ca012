"""Compiled (numba) kernels for the pipeline's element-wise per-step arithmetic: the hand's acceleration cap.

Each kernel performs numpy's operations on every element in numpy's order (no fused multiply-add, no
reassociation), with numpy's minimum / maximum on equal values (the second argument), so its results
equal the numpy expressions they replace bit for bit (tests/pipeline/test_kernels.py); sessions recorded
before them re-run identically. Compiled on the first call and cached on disk (cache=True); warm(), run by
scripts/setup.sh, fills the cache.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def _max(a, b):
    return a if a > b else b  # np.maximum: the second argument on a tie (so -0 / +0 as numpy)


@njit(cache=True, inline="always")
def _min(a, b):
    return a if a < b else b


@njit(cache=True)
def hand_track(q, v, target, target_v, has_target_v, dt, dt_before, speed_frac, lower, upper, velocity,
               acceleration, brake_fraction):
    """trajectory.HandLimiter.track's arithmetic for dt > 0: (command, its velocity)."""
    n = q.shape[0]
    cmd = np.empty(n)
    vel = np.empty(n)
    span = dt + (dt_before if dt_before > 0 else dt)
    for i in range(n):
        a = acceleration[i]
        lo = lower[i]
        hi = upper[i]
        cap = velocity[i] * speed_frac
        dv = a * 0.5 * span
        g = _min(_max(target[i], lo), hi)
        tv = _min(_max(target_v[i], -0.9 * cap), 0.9 * cap) if has_target_v else 0.0
        room = hi - g if tv > 0 else g - lo
        if tv * tv > a * room:
            tv = 0.0
        e = g - q[i]
        ab = brake_fraction * a
        half = 0.5 * ab * dt
        brake = math.sqrt(2.0 * ab * abs(e) + half * half) - 0.5 * ab * dt
        step = e / dt
        want = _min(step, tv + brake) if e >= 0 else _max(step, tv - brake)
        want = _min(_max(want, -cap), cap)
        vi = v[i]
        w = _min(_max(want, vi - dv), vi + dv)
        bound = _max(cap, abs(vi))
        w = _min(_max(w, -bound), bound)
        c = _min(_max(q[i] + w * dt, lo), hi)
        cmd[i] = c
        vel[i] = (c - q[i]) / dt
    return cmd, vel


@njit(cache=True)
def hand_stop(q, v, dt, dt_before, lower, upper, acceleration):
    """trajectory.HandLimiter.stop's arithmetic for dt > 0: (command, its velocity)."""
    n = q.shape[0]
    cmd = np.empty(n)
    vel = np.empty(n)
    span = dt + (dt_before if dt_before > 0 else dt)
    for i in range(n):
        dv = acceleration[i] * 0.5 * span
        vi = v[i]
        w = _max(vi - dv, 0.0) if vi > 0 else _min(vi + dv, 0.0)
        c = _min(_max(q[i] + w * dt, lower[i]), upper[i])
        cmd[i] = c
        vel[i] = (c - q[i]) / dt
    return cmd, vel


def warm() -> None:
    """Compile (or load from the cache) every kernel here for float64 vectors."""
    x = np.zeros(2)
    hand_track(x, x, x, x, True, 0.01, 0.01, 1.0, x - 1.0, x + 1.0, x + 1.0, x + 1.0, 0.8)
    hand_stop(x, x, 0.01, 0.01, x - 1.0, x + 1.0, x + 1.0)
