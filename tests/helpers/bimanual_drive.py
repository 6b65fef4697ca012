"""A scripted bimanual episode that drives the two hands through each other on purpose, through the real
BimanualDriver (both sides' pipelines and the cross-side guard) and each side's real CommandPlanner ticked
at the sender's rate, the robots taken to follow their commands exactly. For tests/bimanual and
bench/bimanual.py: how many targets the guard held, and how many commanded configurations of the two
robots were in contact (checked exactly, with no clearance)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from teleprev.human import smplx
from teleprev.human.mirror import mirror_hand_pose, mirror_wrist
from teleprev.messages import JointSample, Logged, PoseSample
from teleprev.transforms import matrix_to_quat, rpy_to_matrix

HOME = np.array([0.0, -0.27, -0.11, 0.0, -0.85, -1.571])
GLOVE_HZ = 120.0
ARM_NAMES = tuple(f"joint{i}" for i in range(1, 7))
HAND_NAMES = tuple(str(i) for i in range(16))


@dataclass
class DriveResult:
    held: int  # targets the guard held
    colliding_commands: int  # ticks whose two commands put the robots in contact
    ticks: int  # ticks at which both sides commanded
    flagged: int = 0  # recorded step reports flagged cross_side_held
    contacts: list = field(default_factory=list)  # the first few (left link, right link) pairs in contact


def drive_through(rig, guard: bool = True, seconds: float = 4.0, reach_m: float = 0.4) -> DriveResult:
    """Engage at 0.4 s, then move the right wrist `reach_m` towards the left side and the left wrist as far
    towards the right (mirrored), over `seconds` - 1 s, and hold."""
    from teleprev.bimanual import build_bimanual_driver, build_guard
    from teleprev.pipeline.bimanual import BimanualDriver
    from teleprev.pipeline.planner import CommandPlanner

    full = build_bimanual_driver(rig)
    driver = full if guard else BimanualDriver({s: (full.drivers[s], full.inputs[s]) for s in full.drivers})
    checker = build_guard(rig, {s: d.pipeline for s, d in full.drivers.items()}).checker
    checker.clearance_m = 0.0
    checker._reach2 = (checker.robots[0].radius[:, None] + checker.robots[1].radius[None, :]) ** 2
    joints = full.guard.joints
    planners = {s: CommandPlanner.for_pipeline(d.pipeline) for s, d in driver.drivers.items()}
    measured = {s: (HOME.copy(), np.zeros(16)) for s in driver.drivers}
    pose = smplx.hand_pose_from_angles(np.full(15, 0.2), np.zeros(15)).reshape(45)
    rotation = rpy_to_matrix(0.0, 0.0, 0.0)
    result = DriveResult(0, 0, 0)
    step_ns = int(1e9 / GLOVE_HZ)
    t0 = 1_000_000_000
    for k in range(int(seconds * GLOVE_HZ)):
        t = t0 + k * step_ns
        s = min(max((k / GLOVE_HZ - 0.8) / (seconds - 1.0), 0.0), 1.0)
        right_wrist = np.array([0.30, -0.20 + reach_m * s, 1.10])
        for side, (glove, (p, r)) in {"right": (pose, (right_wrist, rotation)),
                                      "left": (mirror_hand_pose(pose), mirror_wrist(right_wrist, rotation))}.items():
            d = rig.sides[side].devices
            arm, hand = measured[side]
            for msg in (Logged(f"/suit/{d['suit']}/wrist", t, PoseSample(t, "suit", p, matrix_to_quat(r))),
                        Logged(f"/arm/{d['arm']}/state", t + 1, JointSample(t, ARM_NAMES, arm.copy())),
                        Logged(f"/hand/{d['hand']}/state", t + 2, JointSample(t, HAND_NAMES, hand.copy())),
                        Logged(f"/glove/{d['glove']}/hand", t + 3, JointSample(t, smplx.HAND_POSE_NAMES, glove))):
                for out in driver.feed(msg).values():
                    result.flagged += sum(1 for topic, payload in out.logged if topic.endswith("/report")
                                          and "cross_side_held" in payload.data.get("flags", []))
        if k == int(0.4 * GLOVE_HZ):
            refused = driver.request_mode("execute", t + 4)
            assert not refused, refused
        for side, updates in driver.take_updates().items():
            for update in updates:
                planners[side].adopt(update)
        ticks = {side: planner.tick(t + 5) for side, planner in planners.items()}
        for side, tick in ticks.items():
            if tick is not None:
                measured[side] = (tick.arm, tick.hand)
        if all(tick is not None for tick in ticks.values()):
            result.ticks += 1
            found = checker.contacts(joints["left"].full(ticks["left"].arm, ticks["left"].hand),
                                     joints["right"].full(ticks["right"].arm, ticks["right"].hand))
            if found:
                result.colliding_commands += 1
                result.contacts = (result.contacts + found)[:5]
    result.held = full.guard.held if guard else 0
    return result
