"""The simulated operator's demonstrations in the physics world, faster than real time.

One episode of one task: the sim operator (devices/teleprev_devices/sim/operator.py) performs it, its glove
and suit samples go through the rig's pipeline (retarget, Corrector) by the PipelineDriver and its
updates through the CommandPlanner at the paced sender's ticks (the same code a live session runs), and
each tick's commands become the drives' targets in a PhysicsWorld that steps in lock step with them, off
the wall clock. The operator watches the world (SimOperator.watch: the objects' poses now), as a person
does, and the episode is judged by teleprev/world/success.py once the operator is back at rest.

    result = run_demo(load_rig(rigs/sim_physics.toml), "pick_place", seed=3)
    result.outcome.success, result.outcome.reason

What the lock step leaves out of the live path: transport and clock noise (each sample is logged its
device's minimum latency after it was taken) and the wall clock (nothing is late). `hand` picks the hand's
side of the pipeline: "corrector" (the rig's), "no_corrector" (the CCN not applied: the retargeted joints
where the exact check finds them free, else the last free target held) or "no_guard" (no self-collision
check at all; a bench's comparison, never a rig's).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from teleprev.assembly import build_driver, build_pipeline
from teleprev.messages import JointSample, Logged, PoseSample
from teleprev.noncollision.corrector import Correction, Prepared
from teleprev.pipeline.driver import InputTopics
from teleprev.pipeline.planner import CommandPlanner
from teleprev.rig import Rig

HandSide = Literal["corrector", "no_corrector", "no_guard"]
HAND_SIDES: tuple[HandSide, ...] = ("corrector", "no_corrector", "no_guard")
SAMPLE_NS = 20_000_000  # world states judged every 20 ms, as tests/world/helpers.py samples them
ENGAGE_S = 0.25  # samples flow this long in preview before the engage, the operator at rest
START_S = 1.0  # the operator begins its episode this long after the samples do: the engage ramp is over
SETTLE_S = 0.3  # after the operator's episode, before the last state is judged


class _HeldCorrector:
    """The hand without the CCN: the retargeted joints where the exact check finds them free, else the
    last free target held (the Corrector's own exact check, its networks never asked)."""

    def __init__(self, corrector):
        self.inner = corrector
        self.checker = corrector.checker
        self.neutral = corrector.neutral

    def prepare(self, q: np.ndarray) -> list[Prepared]:
        return [Prepared(p.q, p.q0, p.report) for p in self.inner.prepare(q)]

    def correct(self, q, previous=None, prepared: Prepared | None = None) -> Correction:
        if prepared is None:
            prepared = self.prepare(np.asarray(q, dtype=float)[None])[0]
        if not prepared.report.colliding:
            return Correction(prepared.q0, "untouched", (), float(np.abs(prepared.q0 - prepared.q).max()))
        held = self.inner._anchor(previous)  # the previous target if free, else the open hand
        links = tuple(prepared.report.colliding_links(self.checker.link_names))
        return Correction(held, "held", links, float(np.abs(held - prepared.q).max()))


class _Unchecked:
    """No self-collision check: the retargeted joints within limits, as they come."""

    def __init__(self, corrector):
        self.model = corrector.model
        self.checker = None

    def prepare(self, q: np.ndarray) -> list[Prepared]:
        q = np.atleast_2d(np.asarray(q, dtype=float))
        return [Prepared(row, self.model.clip(row), None) for row in q]

    def correct(self, q, previous=None, prepared: Prepared | None = None) -> Correction:
        q0 = self.model.clip(np.asarray(q, dtype=float)) if prepared is None else prepared.q0
        return Correction(q0, "untouched", (), 0.0)


def demo_pipeline(rig: Rig, hand: HandSide = "corrector"):
    """The rig's pipeline, its hand side as `hand` says (see the module docstring)."""
    if hand not in HAND_SIDES:
        raise ValueError(f"hand must be one of {', '.join(HAND_SIDES)}, got {hand!r}")
    pipeline = build_pipeline(rig)
    effector = pipeline.effector
    if hand == "corrector" or effector.corrector is None:
        return pipeline
    if hand == "no_corrector":
        effector.corrector = _HeldCorrector(effector.corrector)
    else:
        effector.corrector = _Unchecked(effector.corrector)
        effector.guard.checker = None
        pipeline.motion.swept = None
    return pipeline


@dataclass(frozen=True)
class DemoResult:
    task: str
    seed: int
    hand: HandSide
    outcome: object  # teleprev.world.success.Outcome
    sim_s: float  # simulated seconds
    ticks: int  # commands sent (each to arm and hand)
    actions: dict[str, int] = field(default_factory=dict)  # the hand side's answers: untouched / ccn / ...


@dataclass
class _Stream:
    """One device's samples: taken every period, logged its latency later."""

    period_ns: int
    latency_ns: int
    next_ns: int = 0


def run_demo(rig: Rig, task: str, seed: int, hand: HandSide = "corrector", closed_loop: bool = True,
             pipeline=None) -> DemoResult:
    """One episode of `task` by the sim operator of `seed`, through the rig's pipeline into a physics world
    stepped in lock step (see the module docstring); `closed_loop` False: the operator does not watch."""
    from teleprev.world.layout import task_layout
    from teleprev.world.places import DEFAULT_ANCHOR
    from teleprev.world.success import judge
    from teleprev.world.world import PhysicsWorld
    from teleprev_devices.sim.operator import SimOperator

    pipeline = pipeline if pipeline is not None else demo_pipeline(rig, hand)
    glove, suit, arm_dev, hand_dev = (rig.of_kind(k)[0].name for k in ("glove", "suit", "arm", "hand"))
    inputs = InputTopics.for_devices(glove, suit, arm_dev, hand_dev)
    driver = build_driver(pipeline, inputs)
    planner = CommandPlanner.for_pipeline(pipeline)

    op = SimOperator(seed, task, "fixed")
    anchor = DEFAULT_ANCHOR  # the scene around the TCP at the arm's home, as the sim rig lays it out
    layout = task_layout(task, seed, tuple(anchor), op.spots(0.0))
    world = PhysicsWorld(rig.rig.end_effector, layout, rig.sim.rate_hz)
    if closed_loop:
        op.watch(lambda: world.seen(anchor))
    arm_names, hand_names = pipeline.arm_names, pipeline.effector_names

    engage_ns, lead_ns = round(ENGAGE_S * 1e9), round(START_S * 1e9)
    episode_end_s = op.episode_span(0)[1]
    end_ns = lead_ns + round((episode_end_s + SETTLE_S) * 1e9)
    streams = {"glove": _Stream(round(1e9 / 120), 2_000_000), "suit": _Stream(round(1e9 / 60), 5_000_000),
               "arm": _Stream(10_000_000, 1_000_000), "hand": _Stream(round(1e9 / 90), 1_500_000)}
    tick_ns = round(1e9 / pipeline.cfg.command_rate_hz)
    pending: list[tuple[int, Logged]] = []
    states = []
    next_tick, next_state = tick_ns, 0
    engaged, ticks = False, 0
    actions: dict[str, int] = {}
    t = 0
    step_ns = world.step_ns
    while t <= end_ns:
        op_t = max(0.0, (t - lead_ns) / 1e9)  # at rest until its episode begins
        for name, s in streams.items():
            while s.next_ns <= t:
                pending.append((s.next_ns + s.latency_ns, _sample(name, s.next_ns, op, op_t, world, arm_names,
                                                                 hand_names, inputs)))
                s.next_ns += s.period_ns
        pending.sort(key=lambda p: p[0])
        while pending and pending[0][0] <= t:
            log_ns, msg = pending.pop(0)
            result = driver.advance(Logged(msg.topic, log_ns, msg.payload))
            if result is not None and result.report.get("corrector"):
                a = result.report["corrector"]
                actions[a] = actions.get(a, 0) + 1
        if not engaged and t >= engage_ns and driver.latest.get(inputs.arm) and driver.latest.get(inputs.effector):
            refused = driver.request_mode("execute", t)
            if refused:
                raise RuntimeError(f"engage refused: {refused}")
            engaged = True
        if t >= next_tick:
            for update in driver.take_updates():
                planner.adopt(update)
            tick = planner.tick(t)
            if tick is not None:
                targets = {}
                if tick.arm is not None:
                    targets.update(zip(arm_names, tick.arm.tolist()))
                if tick.hand is not None:
                    targets.update(zip(hand_names, tick.hand.tolist()))
                world.set_targets(targets)
                ticks += 1
            next_tick += tick_ns
        if t >= next_state:
            states.append(world.state())
            next_state += SAMPLE_NS
        world.step()
        t += step_ns
    return DemoResult(task, seed, hand, judge(layout, states), t / 1e9, ticks, actions)


def _sample(device: str, t_ns: int, op, op_t: float, world, arm_names, hand_names, inputs: InputTopics) -> Logged:
    from teleprev.human import smplx

    if device == "glove":
        flexion, abduction = op.hand_angles(op_t)
        pose = smplx.hand_pose_from_angles(flexion, abduction).reshape(45)
        return Logged(inputs.hand, t_ns, JointSample(t_ns, smplx.HAND_POSE_NAMES, pose))
    if device == "suit":
        s = op.state(op_t)
        from teleprev.transforms import matrix_to_quat

        return Logged(inputs.wrist, t_ns, PoseSample(t_ns, "suit", np.asarray(s.wrist_position, dtype=float),
                                                     matrix_to_quat(s.wrist_rotation)))
    names = arm_names if device == "arm" else hand_names
    q, v = world.joint_positions(names), world.joint_velocities(names)
    topic = inputs.arm if device == "arm" else inputs.effector
    return Logged(topic, t_ns, JointSample(t_ns, tuple(names), np.array([q[n] for n in names]),
                                           np.array([v[n] for n in names])))

