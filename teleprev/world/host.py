"""The physics world of a session, run in a process of its own, and the handles that reach it.

    host = WorldHost("leap_hand", task_layout("pour", 7), clock)   # starts the world process
    link = host.link                                # in this process, or any process forked from it
    link.set_targets({"joint1": 0.2})               # the drives' targets by joint name
    link.joint_positions(("joint1",))               # measured
    host.load_layout(layout, robot={...})           # a new episode's scene (the robot where it stands, or placed);
                                                    # returns how the world began it (WorldLink.began)
    mirror = WorldMirror(link)                      # a copy of the world for reading: mirror.sync(); mirror.render()
    host.close()

The world's state lives in a shared memory block (teleprev/world/shared.py) mapped from a memfd, so a
process forked after the host started (the paced command sender) shares it too; the world process is
started with fork+exec (a fresh interpreter: nothing of this process's threads or locks is copied).
"""

from __future__ import annotations

import atexit
import json
import mmap
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

from teleprev.clock import SessionClock
from teleprev.world.layout import Layout
from teleprev.world.shared import (
    ALIVE,
    GENERATION,
    LATE_BATCHES,
    LATE_MAX_NS,
    OUTCOME_SEQ,
    REALTIME,
    REQUESTED,
    SIZE,
    STEPS,
    STOP,
    TIME_NS,
    SharedBlock,
)
from teleprev.world.world import DEFAULT_RATE_HZ

START_TIMEOUT_S = 30.0  # a fresh interpreter importing numpy and mujoco on a loaded machine


@dataclass(frozen=True)
class WorldStats:
    steps: int
    time_ns: int
    late_max_ms: float  # how far behind the session clock a batch of steps started, at most
    late_batches: int  # batches that started more than 10 ms behind
    alive: bool
    realtime: bool  # the world process got SCHED_FIFO


@dataclass(frozen=True)
class WorldOutcome:
    """The task's outcome as the world process last judged it (teleprev/world/success.py)."""

    task: str
    success: bool
    reason: str
    time_ns: int
    generation: int

    @property
    def mark(self) -> str:
        return "success" if self.success else "failure"


class WorldLink:
    """Targets in, joint state out, through the shared block; usable from any process that maps it."""

    def __init__(self, block: SharedBlock):
        self.block = block
        info = block.read_json("info")
        self.effector: str = info["effector"]
        self.joint_names: tuple[str, ...] = tuple(info["joints"])
        self._qpos = {n: v[0] for n, v in info["joints"].items()}
        self._dof = {n: v[1] for n, v in info["joints"].items()}
        self._actuator = {n: v[2] for n, v in info["joints"].items()}
        self.rate_hz = float(info["rate_hz"])

    def _check(self, names: Iterable[str]) -> None:
        unknown = [n for n in names if n not in self._actuator]
        if unknown:
            raise KeyError(f"unknown joints {unknown} (the world has {', '.join(self.joint_names)})")

    def set_targets(self, targets: Mapping[str, float]) -> None:
        self._check(targets)
        values = np.asarray(list(targets.values()), dtype=float)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"joint targets must be finite, got {dict(targets)}")
        self.block.ctrl[[self._actuator[n] for n in targets]] = values

    def targets(self, names: Iterable[str]) -> np.ndarray:
        names = tuple(names)
        self._check(names)
        return self.block.ctrl[[self._actuator[n] for n in names]].copy()

    def joint_state(self, names: Iterable[str]) -> tuple[int, np.ndarray, np.ndarray]:
        """(world time ns, positions, velocities) of these joints at one instant ("vacuum": its command, 0 or 1)."""
        names = tuple(names)
        self._check(names)
        b = self.block
        qa = [self._qpos[n] for n in names]
        da = [self._dof[n] for n in names]

        def read():
            return int(b.header[TIME_NS]), b.qpos[qa].copy(), b.qvel[da].copy()

        t, q, v = b.read_consistent(read)
        switch = [i for i, a in enumerate(qa) if a < 0]
        if switch:
            ctrl = b.ctrl[[self._actuator[names[i]] for i in switch]]
            q[switch], v[switch] = (ctrl >= 0.5).astype(float), 0.0
        return t, q, v

    def joint_positions(self, names: Iterable[str]) -> dict[str, float]:
        names = tuple(names)
        return dict(zip(names, self.joint_state(names)[1].tolist()))

    def snapshot(self, nq: int, nv: int) -> tuple[int, int, np.ndarray, np.ndarray]:
        """(layout generation, world time, qpos[:nq], qvel[:nv]) at one instant."""
        b = self.block
        return b.read_consistent(lambda: (int(b.header[GENERATION]), int(b.header[TIME_NS]), b.qpos[:nq].copy(),
                                          b.qvel[:nv].copy()))

    def running(self) -> tuple[int, dict]:
        """(generation, layout record) of the scene the world runs now."""
        b = self.block
        while True:
            g = int(b.header[GENERATION])
            record = b.read_json("running")
            if int(b.header[GENERATION]) == g:
                return g, record

    def began(self) -> tuple[int, dict]:
        """(generation, {"time_ns", "robot", "placed"}): how the world began the scene it runs now: its time,
        the robot's joint positions at rest, and whether they were placed there (the drives' targets too)
        or kept from the scene before (the drives keep the actuators' targets)."""
        b = self.block
        while True:
            g = int(b.header[GENERATION])
            record = b.read_json("began")
            if int(b.header[GENERATION]) == g:
                return g, record

    def outcome(self) -> WorldOutcome | None:
        """The latest judgement of the running task (None before the first)."""
        b = self.block
        data = b.read_consistent(lambda: b.read_json("outcome"), OUTCOME_SEQ)
        return None if data is None else WorldOutcome(**data)

    def stats(self) -> WorldStats:
        h = self.block.header
        return WorldStats(int(h[STEPS]), int(h[TIME_NS]), int(h[LATE_MAX_NS]) / 1e6, int(h[LATE_BATCHES]),
                          bool(h[ALIVE]), bool(h[REALTIME]))


class WorldHost:
    """Starts and owns the world process of one session (in the session process)."""

    def __init__(self, effector: str, layout: Layout, clock: SessionClock, rate_hz: float = DEFAULT_RATE_HZ,
                 robot: Mapping[str, float] | None = None):
        self._lock = threading.Lock()
        self._fd = os.memfd_create("teleprev-world")
        os.ftruncate(self._fd, SIZE)
        self._buffer = mmap.mmap(self._fd, SIZE)
        self.block = SharedBlock(self._buffer)
        self._request(layout, robot)
        config = {"fd": self._fd, "effector": effector, "rate_hz": rate_hz, "clock_offset_ns": clock.from_monotonic(0)}
        self.process = subprocess.Popen([sys.executable, "-m", "teleprev.world.process", json.dumps(config)],
                                        pass_fds=(self._fd,), stdin=subprocess.DEVNULL)
        atexit.register(self.close)
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self.block.header[ALIVE]:
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.close()
                raise RuntimeError(f"the physics world process did not start (exit status {self.process.returncode})")
            time.sleep(0.01)
        self.link = WorldLink(self.block)

    def _request(self, layout: Layout, robot: Mapping[str, float] | None) -> int:
        self.block.write_json("request", {"layout": layout.to_record(),
                                          "robot": {k: float(v) for k, v in robot.items()} if robot else None})
        self.block.header[REQUESTED] += 1
        return int(self.block.header[REQUESTED])

    def load_layout(self, layout: Layout, robot: Mapping[str, float] | None = None, timeout_s: float = 5.0) -> dict:
        """Run this scene from now on (the robot where it stands, or placed at rest at `robot`); returns, once
        the world runs it, how it began it (WorldLink.began)."""
        # The lock is held until the world has taken the request: a second request written while the world
        # reads the first would tear it (seen as a JSONDecodeError that ended the world's process).
        with self._lock:
            generation = self._request(layout, robot)
            deadline = time.monotonic() + timeout_s
            while self.block.header[GENERATION] < generation:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError("the physics world process did not take the new layout "
                                       f"({'it exited' if self.process.poll() is not None else 'timed out'})")
                time.sleep(0.002)
            return self.link.began()[1]

    def close(self) -> None:
        if self.process.poll() is None:
            self.block.header[STOP] = 1
            try:
                self.process.wait(2.0)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
        atexit.unregister(self.close)


class WorldMirror:
    """A copy of the running world for reading it whole, in the process and thread that use it: object
    states, the camera's pictures. `sync()` copies the world's state over (rebuilding the copy when the
    layout changed) and recomputes what follows from it (positions of every body, contacts)."""

    def __init__(self, link: WorldLink):
        self.link = link
        self.world = None
        self.generation = -1
        self._renderers: dict[tuple, object] = {}

    def sync(self):
        """The mirrored PhysicsWorld, at the world's latest published state."""
        import mujoco

        from teleprev.world.layout import layout_from_record
        from teleprev.world.world import PhysicsWorld

        generation, record = self.link.running()
        if generation != self.generation:
            self.close_renderers()
            self.world = PhysicsWorld(self.link.effector, layout_from_record(record), self.link.rate_hz)
            self.generation = generation
        w = self.world
        g, t, qpos, qvel = self.link.snapshot(w.model.nq, w.model.nv)
        if g != self.generation:  # the layout changed between the two reads: next time
            return w
        with w.lock:
            w.data.qpos[:], w.data.qvel[:] = qpos, qvel
            w.data.ctrl[:] = self.link.block.ctrl[:w.model.nu]
            w.time_ns = t
            mujoco.mj_forward(w.model, w.data)
        return w

    def render(self, view: str, width: int, height: int, depth: bool = False):
        """The picture of a camera of the world now (teleprev/world/camera.py: Frame, with depth if asked)."""
        from teleprev.world.camera import WorldCamera

        world = self.sync()
        key = (view, width, height)
        camera = self._renderers.get(key)
        if camera is None:
            camera = self._renderers[key] = WorldCamera(world, view, width, height)
        return camera.render(depth)

    def close_renderers(self) -> None:
        for camera in self._renderers.values():
            camera.close()
        self._renderers.clear()
