"""The command planner: commands sampled at each tick of the paced sender, from the pipeline's
targets, within the motion limits whatever the ticks' timing; every way commands end; determinism."""

import numpy as np
import pytest

from teleprev.assembly import build_pipeline
from teleprev.pipeline.derivatives import stream_peaks
from teleprev.pipeline.planner import CommandPlanner, ModeUpdate, TargetUpdate
from teleprev.rig import load_rig

PERIOD = 8_333_333
HOME = np.array([0.0, -0.27, -0.11, 0.0, -0.85, -1.571])


@pytest.fixture(scope="module")
def pipeline():
    return build_pipeline(load_rig())  # the default sim rig: xArm6 + LEAP Hand, the shipped models


def _planner(p) -> CommandPlanner:
    return CommandPlanner.for_pipeline(p)


class Script:
    """Updates and ticks, numbered as the driver numbers them."""

    def __init__(self, p, arm_start=HOME):
        self.p, self.seq = p, 0
        self.hand0 = np.zeros(len(p.effector_names))
        self.arm_start = np.asarray(arm_start, dtype=float)

    def mode(self, mode: str, t: int, arm=None) -> ModeUpdate:
        self.seq += 1
        start = self.arm_start if arm is None else arm
        return ModeUpdate(
            self.seq, t, mode, start if mode == "execute" else None, self.hand0 if mode == "execute" else None
        )

    def target(self, t: int, arm, arm_v=None, hand=None, hand_v=None) -> TargetUpdate:
        self.seq += 1
        return TargetUpdate(self.seq, t, None if arm is None else np.asarray(arm, float), arm_v, t,
                            self.hand0 if hand is None else hand, hand_v)


def _run(planner, events, ticks):
    """Adopt each (time, update) at the first tick at or after its time; the sent ticks."""
    events = sorted(events, key=lambda e: e[0])
    sent, k = [], 0
    for t in ticks:
        while k < len(events) and events[k][0] <= t:
            planner.adopt(events[k][1])
            k += 1
        out = planner.tick(int(t))
        if out is not None:
            sent.append(out)
    return sent


def _within(p, sent, slack=1e-6):
    """Every arm command inside the joint limits and, by divided differences on the stamps (each run from
    rest, as a controller measures it), under the speed, acceleration and jerk limits; the hand under its
    acceleration cap."""
    arm, hand = p.motion.arm, p.motion.hand
    t = np.array([s.t_ns for s in sent])
    q = np.array([s.arm for s in sent])
    assert (q >= arm.lower - 1e-12).all() and (q <= arm.upper + 1e-12).all()
    peaks = stream_peaks(t, q)
    assert (peaks.speed <= arm.velocity * (1 + slack)).all(), peaks.speed
    assert (peaks.acceleration <= arm.acceleration * (1 + slack)).all(), peaks.acceleration
    assert (peaks.jerk <= arm.jerk * (1 + slack)).all(), peaks.jerk
    h = stream_peaks(t, np.array([s.hand for s in sent]))
    assert (h.acceleration <= hand.acceleration * (1 + slack)).all(), h.acceleration
    return peaks


def _moving_target(s, t0, n, step=PERIOD, amplitude=0.6, hz=0.5):
    """Targets of a wrist moving the arm sinusoidally, at the glove's rate, with their velocities."""
    out = []
    for k in range(n):
        t = t0 + k * step
        phase = 2 * np.pi * hz * (t - t0) / 1e9
        arm = HOME + amplitude * np.array([np.sin(phase), 0.3 * np.sin(phase), 0.2 * np.sin(phase), 0, 0, 0])
        v = amplitude * 2 * np.pi * hz * np.array([np.cos(phase), 0.3 * np.cos(phase), 0.2 * np.cos(phase), 0, 0, 0])
        out.append((t, s.target(t, arm, v)))
    return out


def test_an_engage_starts_where_the_robot_is_and_every_command_keeps_the_limits(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    goal = np.clip(HOME + 0.5, pipeline.motion.arm.lower, pipeline.motion.arm.upper)
    events = [(t0, s.target(t0, goal)), (t0 + 1, s.mode("execute", t0 + 1))]
    events += [(t0 + k * PERIOD + 2, s.target(t0 + k * PERIOD + 2, goal)) for k in range(1, 240)]
    ticks = t0 + 1 + PERIOD * np.arange(240)
    sent = _run(_planner(pipeline), events, ticks)
    assert np.array_equal(sent[0].arm, HOME) and np.array_equal(sent[0].hand, np.zeros(16))
    assert "engaging" in sent[1].flags
    _within(pipeline, sent)
    assert np.abs(sent[-1].arm - goal).max() < 1e-6  # it got there
    assert "engaging" not in sent[-1].flags


def test_late_ticks_sample_further_along_and_never_burst(pipeline):
    """Ticks that wake up to 40 ms late (a loaded machine without real-time priority): each samples the
    profile at its own instant, so the commands stay within every limit."""
    rng = np.random.default_rng(3)
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 600)
    ticks = t0 + 1 + PERIOD * np.arange(600) + rng.choice([0, 0, 0, 1, 3, 40], 600) * 1_000_000
    ticks = np.unique(ticks)
    sent = _run(_planner(pipeline), events, ticks)
    peaks = _within(pipeline, sent)
    assert peaks.speed.max() > 0.5  # it did move


def test_the_same_updates_at_the_same_ticks_give_the_same_commands(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 200)
    ticks = t0 + 1 + PERIOD * np.arange(200)
    a = _run(_planner(pipeline), events, ticks)
    b = _run(_planner(pipeline), events, ticks)
    assert [x.arm.tobytes() + x.hand.tobytes() for x in a] == [x.arm.tobytes() + x.hand.tobytes() for x in b]


def test_stale_targets_brake_to_rest_then_hold_and_keep_sending(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 240)
    ticks = t0 + 1 + PERIOD * np.arange(480)  # the targets stop after 2 s: stale after the stale limit
    sent = _run(_planner(pipeline), events, ticks)
    _within(pipeline, sent)
    assert len(sent) == len(ticks)  # in execute every tick sends, at rest too
    assert any("targets_stale" in x.flags for x in sent)
    assert np.array_equal(sent[-1].arm, sent[-2].arm) and not sent[-1].arm_v.any()


@pytest.mark.parametrize("first_step_ns", [13_100_000, 25_000_000, 50_000_000])
def test_a_late_first_step_after_an_engage_keeps_the_hand_cap(pipeline, first_step_ns):
    """The tick after an engage's first command woke late: the hand, moving off at once towards a far
    target, stays under its cap as the controller measures it (at rest one cycle before the first)."""
    s = Script(pipeline)
    t0 = 1_000_000_000
    hand_goal = np.clip(np.full(len(pipeline.effector_names), 0.6), pipeline.motion.hand.lower,
                        pipeline.motion.hand.upper)
    events = [(t0, s.target(t0, HOME, hand=hand_goal)), (t0 + 1, s.mode("execute", t0 + 1))]
    events += [(t0 + k * PERIOD + 2, s.target(t0 + k * PERIOD + 2, HOME, hand=hand_goal)) for k in range(1, 60)]
    ticks = np.concatenate([[t0 + 1], t0 + 1 + first_step_ns + PERIOD * np.arange(60)])
    sent = _run(_planner(pipeline), events, ticks)
    assert np.abs(sent[1].hand).max() > 0  # the hand moved off at the late step
    _within(pipeline, sent)


def test_a_joint_braking_onto_its_limit_is_held_there_alone(pipeline):
    """The last resort of a brake: joint6 a hair past its lower limit's way while joint4 brakes fast. Only
    joint6 is held at its limit; joint4 goes on braking within the acceleration limit (holding the whole
    arm at rest at once had commanded 89 rad/s^2 on joint4 under load)."""
    from teleprev.pipeline.trajectory import JointMotion

    arm = pipeline.motion.arm
    planner = _planner(pipeline)
    s = Script(pipeline)
    t0 = 1_000_000_000
    planner.adopt(s.target(t0, HOME))
    planner.adopt(s.mode("execute", t0 + 1))
    first = planner.tick(t0 + 1)
    q = HOME.copy()
    q[5] = arm.lower[5] + 1e-7
    v = np.zeros(6)
    v[3], v[5] = 0.8, -0.05
    planner.state.arm.motion = JointMotion(q, v, np.zeros(6))
    planner.adopt(s.mode("preview", t0 + 2))
    out = planner.tick(t0 + 1 + PERIOD)
    assert "arm_limit_held" in out.flags
    assert out.arm[5] == arm.lower[5] and out.arm_v[5] == 0.0
    assert out.arm_v[3] > 0.5  # joint4 still braking, not stopped at once
    assert abs(out.arm_v[3] - 0.8) <= arm.acceleration[3] * PERIOD / 1e9 * (1 + 1e-9)
    assert first is not None


def test_a_pause_in_the_ticks_starts_again_from_rest_where_the_commands_stood(pipeline):
    """A sender that starved for 120 ms: the controller stood at the last command meanwhile, so the next
    commands start from rest there (measured as the controller measures a resumed stream: within limits)."""
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 600)
    ticks = np.concatenate([t0 + 1 + PERIOD * np.arange(200), t0 + 1 + 120_000_000 + PERIOD * np.arange(200, 400)])
    sent = _run(_planner(pipeline), events, ticks)
    resumed = [i for i, x in enumerate(sent) if "commands_resumed" in x.flags]
    assert len(resumed) == 1
    _within(pipeline, sent)


def test_preview_brakes_to_rest_then_sends_nothing(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 360)
    events.append((t0 + 1_500_000_000, s.mode("preview", t0 + 1_500_000_000)))
    ticks = t0 + 1 + PERIOD * np.arange(600)
    planner = _planner(pipeline)
    sent = _run(planner, events, ticks)
    _within(pipeline, sent)
    last = sent[-1]
    assert not last.active and last.t_ns < ticks[-1] and "stopping" in last.flags
    assert not last.arm_v.any() and not last.hand_v.any() and not planner.active


def test_halt_sends_nothing_more_at_once(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 360)
    halt_at = t0 + 1_000_000_000
    events.append((halt_at, s.mode("halt", halt_at)))
    sent = _run(_planner(pipeline), events, t0 + 1 + PERIOD * np.arange(360))
    assert sent[-1].t_ns < halt_at and max(x.t_ns for x in sent) < halt_at


def test_an_engage_while_braking_carries_on_from_the_commands(pipeline):
    s = Script(pipeline)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME))] + [(t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 600)
    events += [(t0 + 1_200_000_000, s.mode("preview", t0 + 1_200_000_000)),
               (t0 + 1_260_000_000, s.mode("execute", t0 + 1_260_000_000, arm=HOME - 0.3))]  # measured: elsewhere
    sent = _run(_planner(pipeline), events, t0 + 1 + PERIOD * np.arange(600))
    _within(pipeline, sent)  # no jump to the (stale) measured start


def test_driving_a_joint_into_its_limit_stops_at_it_within_the_limits(pipeline):
    """An operator pushing joint 3 past its limit at 2 rad/s: the commands come to rest at the limit within
    the acceleration and jerk limits; none is ever held (clipped) at the limit."""
    arm = pipeline.motion.arm
    s = Script(pipeline)
    t0 = 1_000_000_000
    j, start = 2, HOME.copy()
    start[j] = arm.lower[j] + 0.1
    events = [(t0, s.target(t0, start)), (t0 + 1, s.mode("execute", t0 + 1, arm=start))]
    for k in range(1, 700):  # engaged at the far end, the target then runs into the upper limit at 2 rad/s
        t = t0 + k * PERIOD
        target, v = start.copy(), np.zeros(6)
        if k > 120:
            target[j] = min(start[j] + 2.0 * (k - 120) * PERIOD / 1e9, arm.upper[j] + 0.5)
            v[j] = 2.0 if target[j] < arm.upper[j] + 0.5 else 0.0
        events.append((t, s.target(t, target, v)))
    sent = _run(_planner(pipeline), events, t0 + 1 + PERIOD * np.arange(700))
    q = np.array([x.arm for x in sent])
    assert q[:, j].max() <= arm.upper[j] and arm.upper[j] - q[-1, j] < 1e-6  # it went to the limit, and stays
    assert not any("arm_limit_held" in x.flags for x in sent)
    _within(pipeline, sent)


def test_every_command_taken_can_still_stop_inside_the_limits(pipeline):
    """The invariant behind it: from a state whose hardest stop ends inside the limits, whatever the target
    (a jump to the far side, past the limit, moving) and however late the tick, the next state's stop
    ends inside them too, so braking never has to be cut short at a limit."""
    from teleprev.pipeline.trajectory import JointMotion

    arm, rng = pipeline.motion.arm, np.random.default_rng(11)
    planner = _planner(pipeline)
    checked = 0
    for _ in range(400):
        v = rng.uniform(-2.0, 2.0, 6)
        a = rng.uniform(-8.0, 8.0, 6)
        room = rng.uniform(0.0, 0.6, 6)
        q = np.where(v > 0, arm.upper - room, arm.lower + room)
        m = JointMotion(q, v, a)
        end = arm.stop_position(m)
        if not ((end >= arm.lower) & (end <= arm.upper)).all():
            continue
        checked += 1
        target = np.where(rng.random(6) < 0.5, arm.upper + 0.3, arm.lower - 0.3)
        update = TargetUpdate(1, 0, target, rng.uniform(-2.0, 2.0, 6), 0, np.zeros(16), None)
        planner.state.arm.motion, planner.state.mode = m, "execute"
        flags: list[str] = []
        planner._arm(update, int(rng.uniform(8e6, 40e6)), rng.uniform(0.008, 0.04), 1.0, flags)
        after = arm.stop_position(planner.state.arm.motion)
        assert ((after >= arm.lower - 1e-9) & (after <= arm.upper + 1e-9)).all(), (m, flags)
        assert "arm_limit_held" not in flags
    assert checked > 100


def _reengage(p, planner, pushed):
    """Engage, follow a moving target, brake to rest in preview, then engage again with the measured arm
    `pushed` off the last command (as contact pushes a held arm); the ticks sent, and the last one before."""
    s = Script(p)
    t0 = 1_000_000_000
    events = [(t0, s.target(t0, HOME)), (t0 + 1, s.mode("execute", t0 + 1))] + _moving_target(s, t0 + 2, 240)
    events.append((t0 + 1_000_000_000, s.mode("preview", t0 + 1_000_000_000)))
    first = _run(planner, events, t0 + 1 + PERIOD * np.arange(300))
    held = first[-1].arm
    t1 = t0 + 3_000_000_000
    again = [(t1, s.mode("execute", t1, arm=held + pushed))] + _moving_target(s, t1 + 1, 120)
    return first, _run(planner, again, t1 + 1 + PERIOD * np.arange(120)), held


def _servo_faults(sent) -> list:
    """The sim arm's fault rule (a servo-mode controller: a paused stream starts again where it holds) run
    over the commands as sent."""
    from teleprev.devices import ServoStreamRule

    rule = ServoStreamRule(tuple(f"joint{i}" for i in range(1, 7)), 10.0, 500.0, 10_000_000)
    faults = []
    for x in sent:
        broken = rule.check(x.t_ns, x.arm, lambda: (HOME, np.zeros(6)))
        if broken:
            faults.append(broken.describe())
    return faults


def test_an_engage_from_rest_starts_from_the_command_the_controller_holds(pipeline):
    """Contact pushed the held arm 0.6 mrad: the second engage still starts from the last command, so the
    controller (the sim arm's rule, which is never loosened) sees a smooth stream."""
    pushed = np.array([0.0, 6e-4, -6e-4, 0.0, 3e-4, 0.0])
    first, second, held = _reengage(pipeline, _planner(pipeline), pushed)
    np.testing.assert_array_equal(second[0].arm, held)
    assert _servo_faults(first + second) == []
    _within(pipeline, second)


def test_format_6_engaged_from_the_measured_arm(pipeline):
    """Sessions of format 6 re-run as recorded: from the measured arm, whose 0.6 mrad the controller read as
    a jerk (why format 7 changed it)."""
    from teleprev.pipeline.older_formats import MeasuredEngagePlanner

    pushed = np.array([0.0, 6e-4, -6e-4, 0.0, 3e-4, 0.0])
    first, second, held = _reengage(pipeline, MeasuredEngagePlanner.for_pipeline(pipeline), pushed)
    np.testing.assert_array_equal(second[0].arm, held + pushed)
    assert any("jerks" in f for f in _servo_faults(first + second))


def test_an_arm_held_off_its_command_still_engages_from_it_until_a_halt(pipeline):
    """Contact may hold the arm 0.1 rad off its command (the palm pressed on an object): the controller holds
    the command all the same. After a halt (a fault: the controller stopped and let go) the arm engages from
    where it is measured."""
    planner = _planner(pipeline)
    blocked = np.array([0.0, -0.1, 0.0, 0.0, 0.0, 0.0])
    _, second, held = _reengage(pipeline, planner, blocked)
    np.testing.assert_array_equal(second[0].arm, held)
    planner.adopt(ModeUpdate(10_000, 9_000_000_000, "halt"))
    small = np.full(6, 1e-4)
    planner.adopt(ModeUpdate(10_001, 9_500_000_000, "execute", HOME + small, np.zeros(len(pipeline.effector_names))))
    np.testing.assert_array_equal(planner.tick(9_500_000_001).arm, HOME + small)
