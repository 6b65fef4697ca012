"""Physics sessions recorded for the tests of `teleprev eval --physics` and the re-engage (tests/world).

`record_physics` records a timed session on the physics rig (rigs/sim_physics.toml) through the live
session, as `teleprev record` does. The simulated operator cannot yet finish a task in the few seconds a
test affords, so for a recorded success `CupOnTarget` runs each episode it names in a scene with the cup
already standing on its target: a real scene of the world, recorded on /events/world like any other,
that the world judges a success while the operator's reach (towards where its script put the cup) leaves
the cup alone.
"""

from __future__ import annotations

import io

from rich.console import Console

from teleprev.live.record.cues import Cues
from teleprev.live.record.run import run_timed
from teleprev.live.record.schedule import EpisodeTimes
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.rig import default_rig_path
from teleprev.world.places import SPOTS

PHYSICS_RIG = default_rig_path().parent / "sim_physics.toml"
ON_TARGET = "test: the cup standing on its target"
APART = "test: the cup apart from its target"


class CupOnTarget:
    """Each session episode of `episodes` (counted from 0) runs in a pick_place scene with the cup standing on
    its target: loaded as the episode starts (a session task listener), and again whenever the operator's
    script begins a scene of its own during it (a scene listener: its episodes do not keep the session's
    time). An episode after one of them starts in a scene drawn from the seed, the cup apart from its target."""

    def __init__(self, physics, episodes: set[int]):
        self.physics, self.episodes = physics, episodes
        self.index = -1
        self.on_target = False  # the world runs our scene with the cup on its target

    def episode_started(self, task: str) -> None:
        self.index += 1
        if self.index in self.episodes:
            self._load()
        elif self.on_target:  # the others in a scene drawn from the seed, the cup apart from its target
            _, running = self.physics.link().running()
            self.on_target = False
            self.physics.load_layout("pick_place", running["seed"], running["anchor"], reason=APART)

    def scene_began(self, entry) -> None:
        if entry.reason.startswith("operator episode "):
            self.on_target = False
            if self.index in self.episodes:
                self._load()

    def _load(self) -> None:
        target = SPOTS["pick_place"]["target"]
        spot = (target.x, target.y, 0.0)
        _, running = self.physics.link().running()
        self.on_target = True
        self.physics.load_layout("pick_place", running["seed"], running["anchor"], {"cup": spot, "target": spot},
                                 reason=ON_TARGET)


def record_physics(out, plan: EpisodeTimes, on_target: set[int] = frozenset(), rig=PHYSICS_RIG) -> None:
    rec = LiveSession(RecordOptions(out=out, rig=rig, episode_plan=plan))
    if on_target:
        swap = CupOnTarget(rec.physics, set(on_target))
        rec.context.task_listeners.append(swap.episode_started)
        rec.physics.listeners.append(swap.scene_began)
    rec.start()
    try:
        missing = rec.wait_connected(30.0)
        assert missing == [], missing
        run_timed(rec, plan, Console(file=io.StringIO(), width=120), cues=Cues(io.StringIO(), None))
    finally:
        rec.stop()
