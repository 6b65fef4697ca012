"""The compiled hand limiter (teleprev/pipeline/kernels.py) equals the numpy expressions it replaced, bit
for bit, so sessions recorded with those re-run identically."""

import numpy as np
import pytest

from teleprev.pipeline.trajectory import BRAKE_FRACTION, HandLimiter


def numpy_track(h, q, v, target, target_v, dt, dt_before, speed_frac=1.0):
    """HandLimiter.track as it was written in numpy (the reference)."""
    a = h.acceleration
    cap = h.velocity * speed_frac
    dv = a * 0.5 * (dt + (dt_before if dt_before > 0 else dt))
    target = np.minimum(np.maximum(target, h.lower), h.upper)
    tv = np.zeros_like(q) if target_v is None else np.clip(target_v, -0.9 * cap, 0.9 * cap)
    room = np.where(tv > 0, h.upper - target, target - h.lower)
    tv = np.where(tv * tv > a * room, 0.0, tv)
    e = target - q
    ab = BRAKE_FRACTION * a
    brake = np.sqrt(2.0 * ab * np.abs(e) + (0.5 * ab * dt) ** 2) - 0.5 * ab * dt
    want = np.where(e >= 0, np.minimum(e / dt, tv + brake), np.maximum(e / dt, tv - brake))
    want = np.minimum(np.maximum(want, -cap), cap)
    v_new = np.minimum(np.maximum(want, v - dv), v + dv)
    v_new = np.minimum(np.maximum(v_new, -np.maximum(cap, np.abs(v))), np.maximum(cap, np.abs(v)))
    cmd = np.minimum(np.maximum(q + v_new * dt, h.lower), h.upper)
    return cmd, (cmd - q) / dt


def numpy_stop(h, q, v, dt, dt_before):
    dv = h.acceleration * 0.5 * (dt + (dt_before if dt_before > 0 else dt))
    v_new = np.where(v > 0, np.maximum(v - dv, 0.0), np.minimum(v + dv, 0.0))
    cmd = np.minimum(np.maximum(q + v_new * dt, h.lower), h.upper)
    return cmd, (cmd - q) / dt


def _bits_equal(a, b):
    return np.array_equal(np.asarray(a).view(np.int64), np.asarray(b).view(np.int64))  # -0.0 != +0.0 here


@pytest.fixture
def limiter(rng):
    n = 16
    lower = rng.uniform(-1.0, 0.0, n)
    return HandLimiter(lower, lower + rng.uniform(0.5, 2.0, n), np.full(n, 3.0), np.full(n, 40.0))


def _cases(h, rng, count):
    n = len(h.lower)
    for k in range(count):
        q = rng.uniform(h.lower, h.upper)
        v = rng.normal(0, 2.0, n) * (rng.random(n) < 0.8)
        target = q + rng.normal(0, 0.05 if k % 2 else 0.5, n)
        if k % 7 == 0:
            target[:4] = q[:4]  # on the target: zero errors
            v[:4] = [0.0, -0.0, 0.0, -0.0]
        if k % 11 == 0:
            target[4:8] = h.upper[4:8] + 0.3  # beyond a limit
        target_v = None if k % 3 == 0 else rng.normal(0, 2.0, n) * (rng.random(n) < 0.7)
        if target_v is not None and k % 5 == 0:
            target_v[:3] = -0.0
        dt = (1 / 120, 1 / 60, 0.003, 0.05)[k % 4]
        dt_before = (0.0, 1 / 120, 0.02)[k % 3]
        yield q, v, target, target_v, dt, dt_before, (1.0, 0.5)[k % 2]


def test_compiled_hand_track_and_stop_equal_the_numpy_expressions(limiter, rng):
    for q, v, target, target_v, dt, dt_before, frac in _cases(limiter, rng, 3000):
        got = limiter.track(q, v, target, target_v, dt, dt_before, frac)
        want = numpy_track(limiter, q, v, target, target_v, dt, dt_before, frac)
        assert _bits_equal(got[0], want[0]) and _bits_equal(got[1], want[1])
        got = limiter.stop(q, v, dt, dt_before)
        want = numpy_stop(limiter, q, v, dt, dt_before)
        assert _bits_equal(got[0], want[0]) and _bits_equal(got[1], want[1])


def test_a_step_of_no_time_changes_nothing(limiter):
    q, v = limiter.lower + 0.1, np.ones(16)
    assert limiter.track(q, v, q + 1, None, 0.0, 0.01)[0] is q
    assert limiter.stop(q, v, -1.0, 0.01)[1] is v
