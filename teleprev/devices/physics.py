"""The rig's physics world as the sim plugins reach it (DeviceContext.physics, set when the rig says
`[sim] world = "physics"`).

The world runs in a process of its own (teleprev/world/host.py), started on first use: importing this
module imports no physics engine, so `teleprev --help` and kinematic rigs never load mujoco. Plugins ask:

    physics.link()                 targets in, joint state out (teleprev.world.host.WorldLink), from the
                                   session process or a process forked from it after the world started
    physics.load_layout(task, ...) a new scene (an episode's objects where the operator's script put them)
    physics.mirror()               a copy for reading the whole world in the caller's thread: cameras
                                   (mirror.render(view, w, h, depth)) and object states (mirror.sync().state())

Every scene the world runs is kept with the session time it began and the robot's state then (`layouts`)
and handed to the listeners (the recording stores each as an event, so a session can be played back in its
scenes: teleprev/evaluation/physics.py).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from teleprev.clock import SessionClock

WORLDS = ("kinematic", "physics")


@dataclass(frozen=True)
class LayoutRecord:
    """A scene the world began running (noted at `time_ns`, session clock): Layout.to_record(), why it was
    loaded, and how the world began it (teleprev.world.host.WorldLink.began: the world's time then
    `world_ns`, the robot's joint positions at rest, whether they were placed or kept from the scene before)."""

    time_ns: int
    layout: dict
    reason: str
    world_ns: int = 0
    robot: dict = field(default_factory=dict)
    placed: bool = False

    def to_event(self) -> dict:
        """The teleprev.WorldLayout event's data."""
        return {"layout": self.layout, "reason": self.reason, "world_ns": self.world_ns, "robot": self.robot,
                "placed": self.placed}


@dataclass
class PhysicsAccess:
    clock: SessionClock
    end_effector: str
    rate_hz: float = 500.0
    task: str = "pick_place"  # the scene the world starts with, until a device loads another
    seed: int = 0
    layouts: list[LayoutRecord] = field(default_factory=list)
    listeners: list[Callable[[LayoutRecord], None]] = field(default_factory=list)

    def __post_init__(self):
        self._host = None
        self._eyes = None  # the mirror `seen` reads
        self._closed = False
        self._lock = threading.Lock()

    @property
    def started(self) -> bool:
        return self._host is not None

    def host(self):
        """The world process's host, started on first use (teleprev.world.host.WorldHost)."""
        with self._lock:
            if self._host is None:
                from teleprev.world.host import WorldHost
                from teleprev.world.layout import task_layout

                layout = task_layout(self.task, self.seed)
                self._host = WorldHost(self.end_effector, layout, self.clock, self.rate_hz)
                self._note(layout.to_record(), "start", self._host.link.began()[1])
            return self._host

    def link(self):
        return self.host().link

    def mirror(self):
        from teleprev.world.host import WorldMirror

        return WorldMirror(self.link())

    def load_layout(self, task: str, seed: int, anchor, spots: Mapping[str, tuple[float, float, float]] | None = None,
                    robot: Mapping[str, float] | None = None, reason: str = "") -> dict:
        """Run the scene of `task` from now on (its objects at `spots`, task frame, around `anchor`; drawn from
        `seed` where not given), the robot where it stands or placed at `robot`; returns its layout record."""
        from teleprev.world.layout import task_layout

        layout = task_layout(task, seed, tuple(anchor), dict(spots or {}))
        began = self.host().load_layout(layout, robot)
        record = layout.to_record()
        self._note(record, reason, began)
        return record

    def place_robot(self, positions: Mapping[str, float]) -> None:
        """Put the robot's joints at rest at these positions, the running scene's objects back at their
        starting poses (a device's home at its first connect; not a motion)."""
        from teleprev.world.layout import layout_from_record

        _, record = self.link().running()
        began = self.host().load_layout(layout_from_record(record), positions)
        self._note(record, "robot placed", began)

    def _note(self, record: dict, reason: str, began: dict) -> None:
        entry = LayoutRecord(self.clock.now_ns(), record, reason, int(began["time_ns"]), dict(began["robot"]),
                             bool(began["placed"]))
        self.layouts.append(entry)
        for listener in list(self.listeners):
            listener(entry)

    def seen(self, anchor) -> dict[str, tuple[float, ...]]:
        """What a person watching sees now (teleprev.world.world.PhysicsWorld.seen), from a mirror of the world
        kept for it; callers take turns (the sim operator asks under its own lock)."""
        if self._closed:
            raise RuntimeError("the physics world is closed")
        if self._eyes is None:
            self._eyes = self.mirror()
        return self._eyes.sync().seen(anchor)

    @property
    def closed(self) -> bool:
        return self._closed

    def outcome(self) -> Any:
        """The world's latest judgement of its task (teleprev.world.host.WorldOutcome), None before the world
        started or judged."""
        return self._host.link.outcome() if self._host is not None else None

    def close(self) -> None:
        self._closed = True
        with self._lock:
            if self._host is not None:
                self._host.close()
