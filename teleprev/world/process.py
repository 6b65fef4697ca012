"""The physics world's own process: it steps the one PhysicsWorld of a session on the session clock.

    python -m teleprev.world.process '<json config>'     (started by teleprev/world/host.py: WorldHost)

It runs nothing but the world, so stepping at 500 Hz never waits for the session process's interpreter
lock, and the session's threads (the loop, the preview, the camera, the relay passing commands on) never
wait for the stepping. Every PERIOD_S it takes the targets the actuators wrote into the shared block,
steps up to the session clock's now, and publishes the state (teleprev/world/shared.py); every
JUDGE_PERIOD_S it judges the task from the states of the last second and publishes the outcome. A new
layout asked for (a new episode's scene) is built with the robot where it stands. It ends when asked,
or when the process that started it is gone.

Where permitted it runs at SCHED_FIFO priority WORLD_PRIORITY (teleprev/thread_priority.py, beside the
others): above every ordinary process (on a loaded 2-core machine an ordinary one fell up to 150 ms behind
the clock), below the paced command sender's and the actuators' processes, so the commands never wait for
the world.
"""

from __future__ import annotations

import json
import mmap
import os
import sys
import time
from collections import deque

import numpy as np

from teleprev.thread_priority import WORLD_PRIORITY
from teleprev.world.shared import (
    ALIVE,
    GENERATION,
    LATE_BATCHES,
    LATE_MAX_NS,
    OUTCOME_SEQ,
    PID,
    REALTIME,
    REQUESTED,
    SIZE,
    STEPS,
    STOP,
    TIME_NS,
    SharedBlock,
)

PERIOD_S = 0.002  # a batch of steps this often (one 500 Hz step per batch when on time)
STATE_PERIOD_NS = 20_000_000  # object states kept for judging, 50 per second
JUDGE_PERIOD_NS = 100_000_000
LATE_NS = 10_000_000  # a batch that starts this far behind the clock is counted late


def _realtime() -> bool:
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(WORLD_PRIORITY))
        return True
    except (PermissionError, OSError, AttributeError):
        return False


def _build(effector: str, request: dict, rate_hz: float, now_ns: int, robot: dict[str, float]):
    """The world of a request ({"layout": a layout record, "robot": joint positions to place or null}), the
    robot placed at rest where `robot` and then the request say."""
    from teleprev.world.layout import layout_from_record
    from teleprev.world.world import PhysicsWorld

    world = PhysicsWorld(effector, layout_from_record(request["layout"]), rate_hz, start_ns=now_ns)
    world.place_robot({**robot, **(request.get("robot") or {})})
    return world


def _robot_positions(world) -> dict[str, float]:
    return world.joint_positions(world.compiled.arm_joints + tuple(n for n in world.compiled.effector_joints
                                                                     if n != "vacuum"))


def _began(block: SharedBlock, world, placed: bool) -> None:
    """How the world began the scene it runs now (written before the generation that announces it)."""
    block.write_json("began", {"time_ns": world.time_ns, "robot": _robot_positions(world), "placed": placed})


def _info(world) -> dict:
    m = world.model
    joints = {}
    for name in world.joint_names:
        qpos = int(world._qpos[name]) if name in world._qpos else -1
        dof = int(world._dof[name]) if name in world._dof else -1
        joints[name] = [qpos, dof, int(world._actuator[name])]
    lo, hi = m.actuator_ctrlrange[:, 0].tolist(), m.actuator_ctrlrange[:, 1].tolist()
    return {"effector": world.effector.name, "joints": joints, "nu": int(m.nu), "ctrl_lower": lo, "ctrl_upper": hi,
            "rate_hz": 1e9 / world.step_ns}


def _publish(block: SharedBlock, world) -> None:
    d = world.data
    block.begin_write()
    block.qpos[:len(d.qpos)] = d.qpos
    block.qvel[:len(d.qvel)] = d.qvel
    block.header[TIME_NS] = world.time_ns
    block.end_write()


def _publish_outcome(block: SharedBlock, outcome, generation: int) -> None:
    block.begin_write(OUTCOME_SEQ)
    block.write_json("outcome", {"task": outcome.task, "success": outcome.success, "reason": outcome.reason,
                                 "time_ns": outcome.time_ns, "generation": generation})
    block.end_write(OUTCOME_SEQ)


def serve(config: dict) -> None:
    from teleprev.world.success import judge

    fd = int(config["fd"])
    buffer = mmap.mmap(fd, SIZE)
    block = SharedBlock(buffer)
    parent = os.getppid()
    offset_ns = int(config["clock_offset_ns"])  # session time = CLOCK_MONOTONIC + offset, in every process
    now = lambda: time.monotonic_ns() + offset_ns  # noqa: E731
    effector, rate_hz = config["effector"], float(config["rate_hz"])
    generation = int(block.header[REQUESTED])
    world = _build(effector, block.read_json("request"), rate_hz, now(), {})
    block.write_json("info", _info(world))
    nu = world.model.nu
    block.ctrl[:nu] = world.data.ctrl
    lower, upper = world.model.actuator_ctrlrange[:, 0].copy(), world.model.actuator_ctrlrange[:, 1].copy()
    block.write_json("running", world.layout.to_record())
    _began(block, world, True)
    block.header[GENERATION] = generation
    block.header[PID] = os.getpid()
    block.header[REALTIME] = int(_realtime())
    _publish(block, world)
    block.header[ALIVE] = 1
    states: deque = deque(maxlen=60)
    next_state = next_judge = world.time_ns
    try:
        while not block.header[STOP] and os.getppid() == parent:
            t = now()
            if block.header[REQUESTED] != generation:
                generation = int(block.header[REQUESTED])
                request = block.read_json("request")
                world = _build(effector, request, rate_hz, t, _robot_positions(world))
                if request.get("robot"):  # placed: the drives hold it there until the next command
                    block.ctrl[:nu] = world.data.ctrl
                block.write_json("running", world.layout.to_record())
                _began(block, world, bool(request.get("robot")))
                block.header[GENERATION] = generation
                states.clear()
                next_state = next_judge = world.time_ns
            behind = t - world.time_ns
            if behind > LATE_NS:
                block.header[LATE_BATCHES] += 1
            block.header[LATE_MAX_NS] = max(int(block.header[LATE_MAX_NS]), behind)
            world.data.ctrl[:] = np.clip(block.ctrl[:nu], lower, upper)
            block.header[STEPS] += world.advance_to(t)
            _publish(block, world)
            if world.time_ns >= next_state:
                states.append(world.state())
                next_state = world.time_ns + STATE_PERIOD_NS
            if world.time_ns >= next_judge and states:
                _publish_outcome(block, judge(world.layout, list(states)), generation)
                next_judge = world.time_ns + JUDGE_PERIOD_NS
            time.sleep(max(0.0, PERIOD_S - (now() - t) / 1e9))
    finally:
        block.header[ALIVE] = 0


if __name__ == "__main__":
    serve(json.loads(sys.argv[1]))
