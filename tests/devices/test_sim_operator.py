"""The simulated operator: deterministic, varied, smooth, and in LEAP self-collision now and then."""

import numpy as np
import pytest

from teleprev.retarget.hand import LeapRetargeter
from teleprev_devices.sim.operator import SimOperator
from teleprev_devices.sim.tasks import TASKS

RATE = 120.0


class FakeClock:
    def __init__(self):
        self.start_ns = 0
        self.t_ns = 0

    def now_ns(self):
        return self.t_ns


def trajectory(op, t0, t1, rate=RATE):
    ts = np.arange(t0, t1, 1.0 / rate)
    states = [op.state(t) for t in ts]
    return ts, states


def test_same_seed_same_person_and_other_seeds_differ():
    a, b, c = SimOperator(seed=7), SimOperator(seed=7), SimOperator(seed=8)
    ts = np.linspace(0.0, 20.0, 97)
    for t in ts:
        sa, sb = a.state(t), b.state(t)
        assert np.array_equal(sa.wrist_position, sb.wrist_position)
        assert np.array_equal(sa.wrist_rotation, sb.wrist_rotation)
        assert np.array_equal(sa.flexion, sb.flexion) and np.array_equal(sa.abduction, sb.abduction)
    diff = max(np.abs(a.state(t).wrist_position - c.state(t).wrist_position).max() for t in ts)
    assert diff > 0.01


def test_evaluation_order_does_not_matter():
    a, b = SimOperator(seed=3), SimOperator(seed=3)
    ts = np.linspace(0.0, 30.0, 61)
    forward = [a.state(t).flexion for t in ts]
    b.state(30.0)  # jump ahead first
    backward = [b.state(t).flexion for t in ts[::-1]][::-1]
    assert all(np.array_equal(x, y) for x, y in zip(forward, backward))


def test_repetitions_vary():
    op = SimOperator(seed=1, task="pick_place", mode="fixed")
    ts, states = trajectory(op, 0.0, 45.0, rate=20)
    episodes = sorted({s.episode for s in states})
    assert len(episodes) >= 3
    # Each repetition has its own duration and its own grasp.
    starts = [ts[[s.episode for s in states].index(e)] for e in episodes]
    durations = np.diff(starts)
    assert np.ptp(durations) > 0.2
    grasps = [max(s.flexion[0] for s in states if s.episode == e and s.phase == "move") for e in episodes[:3]]
    assert np.ptp(grasps) > 0.02


@pytest.mark.parametrize("task", TASKS)
def test_every_task_is_smooth(task):
    op = SimOperator(seed=2, task=task, mode="fixed")
    ts, states = trajectory(op, 0.0, 25.0)
    assert {s.task for s in states} == {task}
    phases = {s.phase for s in states}
    assert {"return", "pause"} <= phases and len(phases) >= 8
    pos = np.array([s.wrist_position for s in states])
    rot = np.array([s.wrist_rotation for s in states])
    fingers = np.array([np.r_[s.flexion, s.abduction] for s in states])
    speed = np.linalg.norm(np.diff(pos, axis=0), axis=1) * RATE
    turn = np.arccos(np.clip((np.einsum("nij,nij->n", rot[1:], rot[:-1]) - 1) / 2, -1, 1)) * RATE
    finger_speed = np.abs(np.diff(fingers, axis=0)).max(axis=1) * RATE
    assert speed.max() < 1.5, f"wrist moves at {speed.max():.2f} m/s"
    assert turn.max() < 6.0, f"wrist turns at {turn.max():.2f} rad/s"
    assert finger_speed.max() < 10.0, f"a finger moves at {finger_speed.max():.2f} rad/s"
    # It does move: the wrist travels and the fingers open and close.
    assert np.ptp(pos, axis=0).max() > 0.08 and np.ptp(fingers, axis=0).max() > 0.8
    # A person at a table: in front of the body, between the table (0.70 m) and the chest.
    assert pos[:, 0].min() > 0.15 and pos[:, 2].min() > 0.70 and pos[:, 2].max() < 1.2


@pytest.mark.parametrize("task", TASKS)
def test_some_grasps_put_the_leap_hand_into_self_collision_most_poses_do_not(task, hand, hand_checker):
    retarget = LeapRetargeter(hand)
    op = SimOperator(seed=5, task=task, mode="fixed")
    ts, states = trajectory(op, 0.0, 30.0, rate=10)
    colliding = np.array([hand_checker.collides(retarget(s.hand_pose)) for s in states])
    assert 0.03 < colliding.mean() < 0.5, f"{task}: {colliding.mean():.0%} of poses collide"
    hits = {s.phase for s, c in zip(states, colliding) if c}
    assert not hits & {"reach", "approach", "pause"}, f"{task}: collisions while {hits}"


def test_set_task_switches_after_the_current_phase_and_stays_smooth():
    clock = FakeClock()
    op = SimOperator(seed=4, clock=clock)
    assert op.task == "pick_place"
    clock.t_ns = int(3.3e9)
    before = [op.state(t) for t in np.arange(0, 3.3, 1 / RATE)]
    assert op.set_task("pour")
    after = [op.state(t) for t in np.arange(3.3, 20.0, 1 / RATE)]
    states = before + after
    assert all(s.task == "pick_place" for s in before)
    tasks = [s.task for s in after]
    assert "pour" in tasks
    switch = 3.3 + tasks.index("pour") / RATE
    assert switch < 3.3 + 4.0  # the current phase, a return to rest and a short pause
    pos = np.array([s.wrist_position for s in states])
    assert (np.linalg.norm(np.diff(pos, axis=0), axis=1) * RATE).max() < 1.5
    with pytest.raises(ValueError, match="unknown task"):
        op.set_task("juggle")


def test_fixed_and_cycle_modes():
    fixed = SimOperator(seed=0, task="hang", mode="fixed")
    assert not fixed.set_task("pour")
    assert {fixed.episode(t)[1] for t in np.arange(0, 40, 0.5)} == {"hang"}
    cycle = SimOperator(seed=0, mode="cycle")
    seen = []
    for t in np.arange(0, 120, 0.5):
        task = cycle.episode(t)[1]
        if not seen or seen[-1] != task:
            seen.append(task)
    assert seen[:5] == list(TASKS)


def test_switching_twice_within_an_episode_stays_smooth():
    clock = FakeClock()
    op = SimOperator(seed=6, clock=clock)
    states = []
    t = 0.0
    while t < 2.0:
        states.append(op.state(t))
        t += 1 / RATE
    clock.t_ns = int(2.0e9)
    op.set_task("pour")
    # The cut episode returns to rest and ends; both later switches come while it is returning.
    end = next(s for s in np.arange(2.0, 10.0, 0.01) if op.episode(s)[1] != "pick_place")
    switches = [(end - 0.7, "hang"), (end - 0.3, "box_rotation")]
    for switch_at, task in switches:
        while t < switch_at:
            states.append(op.state(t))
            t += 1 / RATE
        clock.t_ns = int(switch_at * 1e9)
        op.set_task(task)
    while t < 12.0:
        states.append(op.state(t))
        t += 1 / RATE
    tasks = [s.task for s in states]
    assert tasks[-1] == "box_rotation" and "hang" not in tasks  # hang was superseded before it began
    pos = np.array([s.wrist_position for s in states])
    fingers = np.array([s.flexion for s in states])
    assert (np.linalg.norm(np.diff(pos, axis=0), axis=1) * RATE).max() < 1.5
    assert (np.abs(np.diff(fingers, axis=0)) * RATE).max() < 10.0


def test_a_watching_operator_reaches_for_the_cup_where_it_sees_it():
    """Blind, the operator reaches where its script put the cup; watching, where the cup is: moved 5 cm
    further away along x, the grasp (the wrist at rest before closing) lands 5 cm further along x too."""
    blind, watching = SimOperator(seed=3, task="pick_place", mode="fixed"), SimOperator(seed=3, task="pick_place",
                                                                                           mode="fixed")
    cup = watching.spots(0.0)["cup"]
    moved = {"cup": (cup[0] + 0.05, cup[1], -0.30, 0.0), "hand": (0.0, 0.0, 0.0, 0.0)}
    watching.watch(lambda: moved)
    grasp = next(t for t in np.arange(0.0, 10.0, 0.01) if blind.state(t).phase == "grasp")
    shift = watching.state(grasp).wrist_position - blind.state(grasp).wrist_position
    assert shift == pytest.approx([0.05, 0.0, 0.0], abs=1e-9)


def _paced_session(op, clock, starts, end, task="pick_place"):
    """Episode starts at `starts` (seconds) as a session's task listener calls them, the operator's state asked
    for in time order as the devices do; returns (times, episode index at each)."""
    ts = np.arange(0.0, end, 1 / 60)
    pending, episodes = list(starts), []
    for t in ts:
        if pending and t >= pending[0]:
            clock.t_ns = int(pending.pop(0) * 1e9)
            op.on_episode_task(task)
        clock.t_ns = int(t * 1e9)
        episodes.append(op.state(t).episode)
    return ts, np.array(episodes)


def test_a_paced_operator_begins_an_episode_only_at_a_session_start():
    """Session episodes of 3 s, shorter than the operator's pick_place: the first start finds the operator in
    its own episode (it begins the session's at once, from where the hand is); each later start that finds a
    paced episode under way sends the hand back to rest and the operator rests until the next start, where it
    begins at once. No episode of the operator (and so no scene of the physics world) begins in the middle of a
    session's."""
    clock = FakeClock()
    op = SimOperator(seed=3, clock=clock)
    starts = [1.0, 4.0, 7.0, 10.0, 13.0]
    ts, episodes = _paced_session(op, clock, starts, 16.0)
    began = [ts[i] for i in np.flatnonzero(np.diff(episodes)) + 1]
    assert began and [t for t in began if t < starts[1]] == [began[0]], began
    for t in began:  # each at a session's start (the next sample after it), never in the middle of an episode
        assert min(abs(t - s) for s in starts) < 1 / 60 + 1e-9, (t, began)
    for index in set(episodes):
        start, end = op.episode_span(int(index))
        if start >= starts[0]:
            assert any(abs(start - s) < 1e-9 for s in starts), (index, start)


def test_a_paced_operator_moves_smoothly_through_the_rests():
    clock = FakeClock()
    op = SimOperator(seed=5, clock=clock)
    starts = [0.5, 3.0, 5.5, 8.0, 20.0]
    ts = np.arange(0.0, 30.0, 1 / RATE)
    pending, states = list(starts), []
    for t in ts:
        if pending and t >= pending[0]:
            clock.t_ns = int(pending.pop(0) * 1e9)
            op.on_episode_task("pick_place")
        clock.t_ns = int(t * 1e9)
        states.append(op.state(t))
    pos = np.array([s.wrist_position for s in states])
    fingers = np.array([s.flexion for s in states])
    assert (np.linalg.norm(np.diff(pos, axis=0), axis=1) * RATE).max() < 1.5
    assert (np.abs(np.diff(fingers, axis=0)) * RATE).max() < 10.0
    phases = [s.phase for s in states if s.t >= 20.0]
    assert "grasp" in phases  # the long episode at 20 s is a whole one, begun at once


def _phase_start(op, name, after=0.0):
    return next(t for t in np.arange(after, 60.0, 0.01) if op.state(t).phase == name)


def _yaw_between(op, t0, t1):
    """The wrist's turn about the vertical from t0 to t1 (radians)."""
    rel = op.state(t1).wrist_rotation @ op.state(t0).wrist_rotation.T
    return float(np.arctan2(rel[1, 0], rel[0, 0]))


def test_a_watching_operator_twists_the_box_by_what_it_sees_is_left():
    """box_rotation: the twist's aim gives the wrist's turn as well as its position. Seeing the box where it
    lay, the first twist turns the wrist the most one twist turns (BOX_STROKE) about the box's centre; seeing
    it already a quarter turn round, the operator does not twist; blind, it twists as the script planned."""
    from teleprev_devices.sim.operator import REST_WRIST
    from teleprev_devices.sim.tasks import BOX_AIM, BOX_STROKE

    def twist(seen_turn):
        op = SimOperator(seed=3, task="box_rotation", mode="fixed")
        x, y, yaw = op.spots(0.0)["box"]
        if seen_turn is not None:
            seen = {"box": (x, y, -0.26, yaw + seen_turn), "hand": (0.0, 0.0, 0.0, 0.0)}
            op.watch(lambda: seen)
        start = _phase_start(op, "twist")
        end = _phase_start(op, "release", start)
        centre = REST_WRIST[:2] + (x, y)
        radius = [np.linalg.norm(op.state(t).wrist_position[:2] - centre) for t in (start, end)]
        return _yaw_between(op, start, end), radius

    turn, (r0, r1) = twist(0.0)
    assert turn == pytest.approx(BOX_STROKE, abs=0.06)
    assert r1 == pytest.approx(r0, abs=0.015)  # about the box's centre: the wrist keeps its distance to it
    assert twist(np.pi / 2)[0] == pytest.approx(0.0, abs=0.06)
    assert twist(None)[0] == pytest.approx(BOX_AIM, abs=0.06)


@pytest.mark.parametrize("physics", [True, False])
def test_on_a_physics_rig_the_operator_rests_until_the_sessions_first_episode(physics):
    """The robot is engaged as a session's episode begins; on a physics rig, where each episode's scene is laid
    out as it starts, the operator waits for that cue at rest (engaging on a hand in mid-reach would offset the
    robot from the operator's hand by the reach for the whole session). The kinematic rig's operator performs
    from the start."""
    from types import SimpleNamespace

    from teleprev_devices.sim.operator import shared_operator

    clock = FakeClock()
    context = SimpleNamespace(clock=clock, shared={}, task_listeners=[], physics=object() if physics else None)
    op = shared_operator(context, "suit", 0, "")
    rest = op.state(0.0).wrist_position
    moved = max(np.linalg.norm(op.state(t).wrist_position - rest) for t in np.arange(0.0, 4.0, 0.1))
    if not physics:
        assert moved > 0.05
        return
    assert moved < 0.01  # tremor only
    clock.t_ns = int(4e9)
    for listener in context.task_listeners:
        listener("pick_place")
    (index, _), start = op.episode(4.0), op.episode_span(op.episode(4.0)[0])[0]
    assert start == pytest.approx(4.0) and index == 1
    assert max(np.linalg.norm(op.state(t).wrist_position - rest) for t in np.arange(4.0, 8.0, 0.1)) > 0.05


def test_a_watching_operator_sets_the_cup_down_until_it_sees_it_on_the_table_then_eases_its_grip():
    """pick_place: after lowering the cup to a centimetre over the table as planned, the operator lowers it
    by what it sees: the held cup seen 3 cm up, the wrist comes down until the cup's base would be SET_DOWN
    up (blind: the planned centimetre). Then it lets go with its fingers still curled round the cup (the
    resting hand's are straighter), and only lifts the hand once the grip is eased."""
    from teleprev.devices import smplx
    from teleprev_devices.sim.tasks import SET_DOWN, TABLE_Z

    def set_down(watching: bool):
        op = SimOperator(seed=3, task="pick_place", mode="fixed")
        if watching:
            x, y, _ = op.spots(0.0)["target"]
            seen = {"cup": (x, y, TABLE_Z + 0.03, 0.0), "hand": (0.0, 0.0, 0.0, 0.0)}
            op.watch(lambda: seen)
        start = _phase_start(op, "set down")
        release = _phase_start(op, "release", start)
        lift = _phase_start(op, "retreat", release)
        dz = op.state(release).wrist_position[2] - op.state(start).wrist_position[2]
        return dz, op, release, lift

    # The same seed sways the wrist alike either way: the difference is the watching operator's.
    dz, op, release, lift = set_down(watching=True)
    assert dz - set_down(watching=False)[0] == pytest.approx(SET_DOWN - 0.03 + 0.01, abs=1e-4)
    curled = [smplx.JOINT_INDEX[f"{f}1"] for f in ("index", "middle", "ring", "pinky")]
    assert op.state(lift - 0.01).flexion[curled].min() > 0.4  # grasps.rest's are 0.2-0.35
    assert abs(op.state(lift - 0.01).wrist_position[2] - op.state(release).wrist_position[2]) < 0.01  # (it sways)
