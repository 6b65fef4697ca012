"""The compiled hand limiter (teleprev/kernels/motion.py) equals the numpy expressions it replaced, bit
for bit, so sessions recorded with those re-run identically."""

import numpy as np
import pytest

from teleprev.pipeline.derivatives import stream_peaks
from teleprev.pipeline.older_formats import TargetFrameHandLimiter
from teleprev.pipeline.trajectory import BRAKE_FRACTION, HandLimiter, JointMotion


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
    """Formats up to 8's limiter (the numpy expressions' envelope: in the target's frame only)."""
    n = 16
    lower = rng.uniform(-1.0, 0.0, n)
    return TargetFrameHandLimiter(lower, lower + rng.uniform(0.5, 2.0, n), np.full(n, 3.0), np.full(n, 40.0))


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


# ---- the fused kernels: Motion's target velocity estimates with the hand's cap and the arm's plan -----
def numpy_estimate(target, before, before_v, gap, keep):
    """Motion's feed-forward estimate as it was written in numpy: (target - before) / gap, smoothed."""
    raw = (target - before) / gap
    return raw if before_v is None else keep * before_v + (1.0 - keep) * raw


def test_hand_command_equals_the_estimate_then_track_or_stop(limiter, rng):
    from teleprev.kernels.motion import ESTIMATE_BLEND, ESTIMATE_NONE, ESTIMATE_RAW, ESTIMATE_ZERO

    for k, (q, v, target, target_v, dt, dt_before, frac) in enumerate(_cases(limiter, rng, 2000)):
        before = target - rng.normal(0, 0.01, len(q))
        before_v = target_v if target_v is not None else np.zeros_like(q)
        keep = float(np.exp(-dt * 1e9 / 30e6))
        estimate = (ESTIMATE_NONE, ESTIMATE_ZERO, ESTIMATE_RAW, ESTIMATE_BLEND)[k % 4]
        rows, unchanged = limiter.command(q, v, target, estimate, before, before_v, keep, dt, dt_before, frac)
        tv = {ESTIMATE_NONE: None, ESTIMATE_ZERO: np.zeros_like(target),
              ESTIMATE_RAW: numpy_estimate(target, before, None, dt, keep),
              ESTIMATE_BLEND: numpy_estimate(target, before, before_v, dt, keep)}[estimate]
        want = numpy_track(limiter, q, v, target, tv, dt, dt_before, frac)
        assert _bits_equal(rows[0], want[0]) and _bits_equal(rows[1], want[1])
        if tv is not None:
            assert _bits_equal(rows[2], tv)
        assert unchanged == (not np.any(want[0] != q))
        rows, unchanged = limiter.command(q, v, None, ESTIMATE_NONE, q, q, 0.0, dt, dt_before, frac)
        want = numpy_stop(limiter, q, v, dt, dt_before)
        assert _bits_equal(rows[0], want[0]) and _bits_equal(rows[1], want[1])
    q, v = limiter.lower + 0.1, np.ones(16)
    rows, unchanged = limiter.command(q, v, q + 1, ESTIMATE_ZERO, q, q, 0.0, 0.0, 0.01)
    assert unchanged and _bits_equal(rows[0], q) and _bits_equal(rows[1], v)  # a step of no time: as it was


class ReferenceArmGenerator:
    """ArmGenerator.track and .stop as they were written in Python floats (the reference)."""

    def __init__(self, g):
        self.g = g

    def _run(self, s, dt, velocity, target, target_v):
        g = self.g
        inp = g._inp
        tv = g._zero if target_v is None else target_v
        cv, vmax, vmin, cp, base = [], [], [], [], []
        for q, v, w, m, t in zip(s.q.tolist(), s.v.tolist(), tv, velocity, target if target is not None else tv):
            cv.append(v - w)
            vmax.append(m - w)
            vmin.append(-m - w)
            if target is None:
                base.append(q + w * dt)
            else:
                cp.append(q - (t - w * dt))
        inp.current_velocity, inp.current_acceleration, inp.max_velocity, inp.min_velocity = (
            cv,
            s.a.tolist(),
            vmax,
            vmin,
        )
        if target is None:
            inp.control_interface, inp.current_position = g._velocity_interface, g._zero
        else:
            inp.control_interface, inp.current_position = g._position, cp
            base = target
        if g._otg.calculate(inp, g._traj).value < 0:
            return None
        q, v, a = g._traj.at_time(dt if dt > 0.0 else 0.0)
        return (JointMotion(np.array([b + x for b, x in zip(base, q)]), np.array([w + x for w, x in zip(tv, v)]),
                            np.array(a)), g._traj.duration)

    def track(self, s, target, target_v, dt, speed_frac=1.0):
        g = self.g
        lower, upper, acceleration = g.lower.tolist(), g.upper.tolist(), g.acceleration.tolist()
        velocity = g.velocity.tolist() if speed_frac == 1.0 else [m * speed_frac for m in g.velocity.tolist()]
        target = [lo if t < lo else hi if t > hi else t for t, lo, hi in zip(target.tolist(), lower, upper)]
        tv = None
        if target_v is not None:
            tv = []
            for w, t, m, lo, hi, acc in zip(target_v.tolist(), target, velocity, lower, upper, acceleration):
                cap = 0.9 * m
                w = -cap if w < -cap else cap if w > cap else w
                room = hi - t if w > 0 else t - lo
                tv.append(0.0 if w * w > acc * room else w)
        out = self._run(s, dt, velocity, target, tv)
        if out is None:
            return self.stop(s, dt), False
        return out[0], out[1] <= dt

    def stop(self, s, dt):
        out = self._run(s, dt, np.maximum(self.g.velocity, np.abs(s.v)).tolist(), None, None)
        if out is None:
            return JointMotion.rest(s.q)
        return JointMotion.rest(out[0].q) if out[0].at_rest else out[0]


@pytest.fixture
def generator(rng):
    from teleprev.pipeline.trajectory import ArmGenerator

    n = 6
    lower = rng.uniform(-3.0, -1.0, n)
    return ArmGenerator(lower, lower + rng.uniform(2.0, 5.0, n), np.full(n, 2.0), np.full(n, 8.0), np.full(n, 60.0))


def _arm_cases(g, rng, count):
    n = len(g.lower)
    for k in range(count):
        q = rng.uniform(g.lower, g.upper)
        if k % 9 == 0:
            q[:2] = g.upper[:2] - rng.uniform(0, 0.01, 2)  # at a limit, heading out
        s = JointMotion(q, rng.normal(0, 1.0, n) * (rng.random(n) < 0.8), rng.normal(0, 4.0, n) * (rng.random(n) < 0.8))
        if k % 13 == 0:
            s = JointMotion.rest(q)
        target = q + rng.normal(0, 0.02 if k % 2 else 0.4, n)
        if k % 11 == 0:
            target[2:4] = g.upper[2:4] + 0.2
        target_v = None if k % 3 == 0 else rng.normal(0, 1.5, n) * (rng.random(n) < 0.7)
        yield s, target, target_v, (1 / 120, 1 / 60, 0.003, 0.05)[k % 4], (1.0, 0.5)[k % 2]


def _same_motion(a, b):
    return _bits_equal(a.q, b.q) and _bits_equal(a.v, b.v) and _bits_equal(a.a, b.a) and a.at_rest == b.at_rest


def test_the_arm_generator_equals_its_python_float_reference(generator, rng):
    ref = ReferenceArmGenerator(generator)
    for s, target, target_v, dt, frac in _arm_cases(generator, rng, 1500):
        got, want = generator.track(s, target, target_v, dt, frac), ref.track(s, target, target_v, dt, frac)
        assert _same_motion(got[0], want[0]) and got[1] == want[1]
        assert _same_motion(generator.stop(s, dt), ref.stop(s, dt))


def test_the_arm_plan_with_motions_estimate_equals_feedforward_then_track(generator, rng):
    """Motion's feed-forward (the estimate, the target moved on by `ahead`) then track, as numpy and
    Python floats computed them; and follow's limit hold and tolerance test as numpy's."""
    from teleprev.kernels.motion import ESTIMATE_BLEND, ESTIMATE_HELD, ESTIMATE_RAW, ESTIMATE_ZERO
    from teleprev.pipeline.trajectory import PLAN_ESTIMATE, PLAN_GOAL

    ref = ReferenceArmGenerator(generator)
    held_seen = 0
    for k, (s, target, target_v, dt, frac) in enumerate(_arm_cases(generator, rng, 1500)):
        before = target - rng.normal(0, 0.005, len(target))
        before_v = target_v if target_v is not None else np.zeros_like(target)
        gap_ns = int(rng.integers(1, 100_000_000))
        keep, ahead = float(np.exp(-gap_ns / 30e6)), float(rng.choice([0.0, 0.004, 0.05]))
        estimate = (ESTIMATE_HELD, ESTIMATE_ZERO, ESTIMATE_RAW, ESTIMATE_BLEND)[k % 4]
        if estimate == ESTIMATE_HELD:
            want_v = before_v
        elif estimate == ESTIMATE_ZERO:
            want_v = np.zeros_like(target)
        else:
            want_v = numpy_estimate(
                target, before, before_v if estimate == ESTIMATE_BLEND else None, gap_ns / 1e9, keep
            )
        goal = target + want_v * ahead
        plan = generator.plan(s, target, dt, frac, estimate, before, before_v, gap_ns / 1e9, keep, ahead)
        assert _bits_equal(plan[PLAN_ESTIMATE], want_v) and _bits_equal(plan[PLAN_GOAL], goal)
        out = generator.follow(s, plan, dt, 0.02)
        want = ref.track(s, goal, want_v, dt, frac)
        if out is None:
            continue
        motion, reached, command, held, close = out
        assert _same_motion(motion, want[0]) and reached == want[1]
        inside = np.minimum(np.maximum(motion.q, generator.lower), generator.upper)
        assert held == (not (inside == motion.q).all()) and _bits_equal(command, inside if held else motion.q)
        assert close == (float(np.abs(motion.q - goal).max()) < 0.02)
        held_seen += held
    assert held_seen > 10


def test_stops_inside_answers_as_the_exact_stop(generator, rng):
    """The braking-distance bound (kernels.far_from_limits) only skips ruckig's exact stop where that stop
    ends inside the limits: stops_inside answers as the exact stop does, near the limits and far from them."""
    from teleprev.kernels.motion import far_from_limits

    g, n = generator, len(generator.lower)
    skipped = exact_outside = 0
    for k in range(3000):
        q = rng.uniform(g.lower, g.upper)
        if k % 2:
            side = rng.integers(0, 2, n).astype(bool)
            q = np.where(side, g.upper - rng.uniform(0, 0.3, n), g.lower + rng.uniform(0, 0.3, n))
        m = JointMotion(q, rng.uniform(-1.0, 1.0, n) * g.velocity, rng.uniform(-1.0, 1.0, n) * g.acceleration)
        end = g.stop_position(m)
        exact = bool(((end >= g.lower) & (end <= g.upper)).all())
        assert g.stops_inside(m) == exact
        far = far_from_limits(m.q, m.v, m.a, g.lower, g.upper, g.acceleration, g.jerk)
        assert exact or not far
        skipped += far
        exact_outside += not exact
    assert skipped > 300 and exact_outside > 300


def test_the_targets_velocity_estimate_is_numpys_bits(rng):
    """TargetEstimates (the planner's feed-forward, one kernel call) gives what its numpy arithmetic gave:
    zero without a usable target before, the raw difference quotient without an estimate before, else the
    blend; recorded sessions re-run on these bits."""
    import math

    from teleprev.pipeline.motion import FEEDFORWARD_MAX_GAP_NS, FEEDFORWARD_TAU_NS
    from teleprev.pipeline.planner import EstimateState, TargetEstimates

    estimates = TargetEstimates(True, FEEDFORWARD_TAU_NS)
    kinds = set()
    for k in range(3000):
        n = (6, 16)[k % 2]
        before, before_v, target = rng.normal(0, 1, n), rng.normal(0, 2, n), rng.normal(0, 1, n)
        gap = int(rng.choice([0, 1, 8_333_333, 16_666_667, FEEDFORWARD_MAX_GAP_NS, FEEDFORWARD_MAX_GAP_NS + 1]))
        est = EstimateState(hand_ns=1_000_000_000 - gap, hand_q=None if k % 7 == 0 else before,
                            hand_v=None if k % 3 == 0 else before_v)
        got, _ = estimates.hand(est, target, 1_000_000_000)
        if est.hand_q is None or not 0 < gap <= FEEDFORWARD_MAX_GAP_NS:
            want, kind = np.zeros(n), "zero"
        elif est.hand_v is None:
            want, kind = (target - before) / (gap / 1e9), "raw"
        else:
            want, kind = (
                numpy_estimate(target, before, before_v, gap / 1e9, math.exp(-gap / FEEDFORWARD_TAU_NS)),
                "blend",
            )
        assert _bits_equal(got, want), kind
        kinds.add(kind)
    assert kinds == {"zero", "raw", "blend"}


def test_a_target_met_moving_short_of_a_joint_limit_is_followed_within_the_cap():
    """A still target a little short of the upper limit whose velocity estimate still says it moves towards
    the limit (a fist closing, then held): the joint, met moving with the target, closed in faster than it
    could stop before the limit, and was held there, past the cap (formats up to 8: up to 1.84x at 120 Hz,
    as the audit measures it). Now it keeps the braking envelope towards the limit too."""
    dt_ns = 8_333_333
    worst = {}
    for cls in (TargetFrameHandLimiter, HandLimiter):
        h = cls(np.array([-1.0]), np.array([1.0]), np.array([6.0]), np.array([200.0]))
        worst[cls] = 0.0
        for target_v in (0.5, 1.0, 1.5, 2.0, 3.0):
            for gap in (0.0, 0.005, 0.01, 0.02):
                q, v, commands = np.array([0.6]), np.zeros(1), [np.array([0.6])]
                target = np.array([1.0 - gap])
                for _ in range(120):
                    q, v = h.track(q, v, target, np.array([target_v]), dt_ns / 1e9, dt_ns / 1e9)
                    commands.append(q)
                peaks = stream_peaks(np.arange(len(commands), dtype=np.int64) * dt_ns, np.array(commands))
                worst[cls] = max(worst[cls], float(peaks.acceleration.max()) / 200.0)
                assert max(c[0] for c in commands) <= 1.0
    assert worst[TargetFrameHandLimiter] > 1.5, worst
    assert worst[HandLimiter] <= 1.0 + 1e-9, worst
