"""`teleprev eval --physics`: a session played into the physics world from its recorded scenes, and each
episode judged by its outcome, twice: with the recorded commands, and with the commands the current
pipeline re-computes (teleprev/evaluation/reproduce.py).

The world is rebuilt as the session's world began each scene (/events/world: the layout, the world's time
then, the robot's joint positions at rest and whether they were placed), and stepped as fast as it goes, not
on the wall clock. Each command becomes the drives' targets at the instant its actuator wrote it
(/command/wire, where the actuator has a process of its own; else at its tick, when the paced sender wrote
it), as the sim arm and hand made it; a re-computed command at the instant the recorded command of the same
tick was written. Object states are kept and the task judged (teleprev/world/success.py)
at the world process's own periods, and an episode's outcome is the last judgement before the live session
asked for it (the log time of its recorded mark; the stop's stamp where none was recorded).

The regression gate compares the two plays in the same deterministic world: an episode that succeeds with
the recorded commands and fails with the re-computed ones is a regression, named by the episode. (The
recorded mark itself is compared with the play of the recorded commands: `agree`; a play that does not
reproduce a mark says that the world did not, not that the pipeline changed.)
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.errors import SessionError
from teleprev.evaluation.command_tracks import CommandTrack
from teleprev.messages import Event
from teleprev.session.reader import SessionReader


@dataclass(frozen=True)
class Scene:
    """A scene the live world began (a teleprev.WorldLayout event)."""

    world_ns: int  # the world's time when it began it
    layout: dict  # Layout.to_record()
    robot: dict[str, float]  # joint positions at rest then
    placed: bool  # the drives' targets reset to `robot` (else kept from the scene before)
    reason: str


@dataclass(frozen=True)
class Commands:
    """One actuator's commands as they reached the world: at `apply_ns` (sorted) the joints `names` got
    the targets `positions` (one row each)."""

    names: tuple[str, ...]
    apply_ns: np.ndarray
    positions: np.ndarray


@dataclass(frozen=True)
class Judgement:
    mark: str  # "success" | "failure"
    reason: str


@dataclass(frozen=True)
class EpisodePlay:
    """One episode's outcomes: as the live world marked it, and played with each set of commands."""

    episode: int
    task: str
    recorded: str | None  # the live world's mark (None: not judged)
    recorded_reason: str
    replayed: str | None  # the recorded commands played (None: the episode never stopped in a scene)
    replayed_reason: str
    recomputed: str | None  # the re-computed commands played
    recomputed_reason: str

    @property
    def agree(self) -> bool:
        return self.recorded is None or self.replayed == self.recorded

    @property
    def regressed(self) -> bool:
        return self.replayed == "success" and self.recomputed != "success"

    def describe_regression(self) -> str:
        return (f"episode {self.episode} ({self.task}): success with the recorded commands, "
                f"{self.recomputed or 'not judged'} with the re-computed ones: {self.recomputed_reason}")


def read_scenes(reader: SessionReader, path: Path) -> list[Scene]:
    """The scenes the session's world ran, in order; a SessionError when the session has none it can restore."""
    scenes = []
    for msg in reader.messages([topics.WORLD]):
        data = msg.payload.data if isinstance(msg.payload, Event) else {}
        where = f"{topics.WORLD} at log time {msg.log_time_ns}"
        if "robot" not in data or "world_ns" not in data:
            raise SessionError(f"{where}: the scene does not say where the robot stood when the world began it "
                               "(recorded before format 7): it cannot be played again", str(path))
        scenes.append(Scene(int(data["world_ns"]), data["layout"], {k: float(v) for k, v in data["robot"].items()},
                            bool(data.get("placed")), str(data.get("reason", ""))))
    if not scenes:
        raise SessionError(f"no scenes on {topics.WORLD}: the session was not recorded on a physics rig "
                           '([sim] world = "physics")', str(path))
    scenes.sort(key=lambda s: s.world_ns)
    return scenes


def read_wire_times(reader: SessionReader) -> dict[str, dict[int, int | None]]:
    """Per actuator kind ("arm", "hand"): command stamp -> when its actuator wrote it (None: it was not taken)."""
    out: dict[str, dict[int, int | None]] = {"arm": {}, "hand": {}}
    if topics.COMMAND_WIRE not in reader.schemas:  # actuators without a process of their own: sent at the tick
        return out
    for msg in reader.messages([topics.COMMAND_WIRE]):
        data = msg.payload.data if isinstance(msg.payload, Event) else {}
        kind = data.get("kind")
        if kind in out and "t_ns" in data:
            out[kind][int(data["t_ns"])] = msg.payload.stamp_ns if data.get("sent", True) else None
    return out


def read_judged_times(reader: SessionReader) -> dict[int, int]:
    """Per episode the live world judged: when the session loop asked it (the log time of its mark, which
    may come after the stop's own stamp: the mark is the world's judgement at that instant)."""
    out = {}
    for msg in reader.messages([topics.EPISODE]):
        data = msg.payload.data if isinstance(msg.payload, Event) else {}
        if data.get("event") == "outcome" and data.get("source") == "physics":
            out[int(data["episode"])] = msg.log_time_ns
    return out


def commands(track: CommandTrack, names: tuple[str, ...], column: str, wire: dict[int, int | None]) -> Commands:
    """The `column` ("recorded" or "rerun") of a CommandTrack as it reaches the world: each at its recorded
    write (its stamp where none was recorded), those the actuator did not take left out."""
    values = getattr(track, column)
    keep = ~np.isnan(values).any(axis=1)
    at, rows = [], []
    for stamp, row in zip(track.t_ns[keep].tolist(), values[keep]):
        written = wire.get(stamp, stamp)
        if written is not None:
            at.append(written)
            rows.append(row)
    order = np.argsort(np.asarray(at, dtype=np.int64), kind="stable")
    return Commands(names, np.asarray(at, dtype=np.int64)[order],
                    np.asarray(rows, dtype=float).reshape(len(at), len(names))[order])


def play(effector: str, rate_hz: float, scenes: list[Scene], sides: list[Commands],
         stops: list[int]) -> tuple[dict[int, Judgement], float]:
    """The world's judgement in force at each of `stops` (session times), playing `sides` into the scenes;
    and the world seconds stepped. Only the scenes some stop falls in are stepped."""
    from teleprev.world.layout import layout_from_record
    from teleprev.world.process import JUDGE_PERIOD_NS, STATE_PERIOD_NS
    from teleprev.world.success import judge
    from teleprev.world.world import PhysicsWorld

    merged = sorted((int(t), i, k) for i, side in enumerate(sides) for k, t in enumerate(side.apply_ns.tolist()))
    out: dict[int, Judgement] = {}
    targets: dict[str, float] = {}
    stepped_ns = 0
    c = 0  # the next command in `merged`
    for n, scene in enumerate(scenes):
        end = scenes[n + 1].world_ns if n + 1 < len(scenes) else None
        inside = sorted(s for s in stops if s >= scene.world_ns and (end is None or s < end))
        if scene.placed:
            targets = dict(scene.robot)
        if not inside:  # not stepped: its commands only move the targets on
            while c < len(merged) and (end is None or merged[c][0] < end):
                targets.update(_row(sides, merged[c]))
                c += 1
            continue
        world = PhysicsWorld(effector, layout_from_record(scene.layout), rate_hz, start_ns=scene.world_ns)
        world.place_robot(scene.robot)
        world.set_targets(targets)
        step = world.step_ns

        def grid(t: int) -> int:  # the world's step a time falls in (a command written then runs from it)
            return scene.world_ns + max(0, t - scene.world_ns) // step * step

        states: deque = deque(maxlen=60)  # as teleprev/world/process.py keeps them
        next_state = next_judge = world.time_ns
        latest: Judgement | None = None
        for stop in inside:
            last = grid(stop)
            while True:
                world.advance_to(min(next_state, next_judge, grid(merged[c][0]) if c < len(merged) else last, last))
                while c < len(merged) and grid(merged[c][0]) <= world.time_ns:
                    row = _row(sides, merged[c])
                    targets.update(row)
                    world.set_targets(row)
                    c += 1
                if world.time_ns >= next_state:
                    states.append(world.state())
                    next_state = world.time_ns + STATE_PERIOD_NS
                if world.time_ns >= next_judge and states:
                    outcome = judge(world.layout, list(states))
                    latest = Judgement(outcome.mark, outcome.reason)
                    next_judge = world.time_ns + JUDGE_PERIOD_NS
                if world.time_ns >= last:
                    break
            if latest is not None:
                out[stop] = latest
        stepped_ns += world.time_ns - scene.world_ns
        while c < len(merged) and (end is None or merged[c][0] < end):  # the rest of the scene's commands
            targets.update(_row(sides, merged[c]))
            c += 1
    return out, stepped_ns / 1e9


def _row(sides: list[Commands], entry: tuple[int, int, int]) -> dict[str, float]:
    _, i, k = entry
    return dict(zip(sides[i].names, sides[i].positions[k].tolist()))


@dataclass
class PhysicsPlay:
    episodes: list[EpisodePlay]
    world_s: float  # world seconds stepped, both plays together
    wall_s: float  # of the two plays

    @property
    def agree(self) -> bool:
        return all(e.agree for e in self.episodes)

    @property
    def regressions(self) -> list[str]:
        return [e.describe_regression() for e in self.episodes if e.regressed]

    def to_report(self) -> dict:
        return {"episodes": [asdict(e) | {"agree": e.agree, "regressed": e.regressed} for e in self.episodes],
                "agree": self.agree, "regressions": self.regressions, "world_s": self.world_s,
                "wall_s": self.wall_s}


def play_session(rerun) -> PhysicsPlay:
    """Both plays of a re-run session (reproduce.Rerun) in the physics world, episode by episode."""
    started = time.perf_counter()
    path = Path(rerun.session)
    world = rerun.metadata.get("world", {})
    if world.get("world") != "physics":
        raise SessionError('not recorded on a physics rig ([sim] world = "physics"): nothing to play into '
                           "the world", str(path))
    effector, rate_hz = world.get("end_effector", rerun.effector.name), float(world.get("rate_hz", 500.0))
    with SessionReader(path) as reader:
        scenes = read_scenes(reader, path)
        wire = read_wire_times(reader)
        asked = read_judged_times(reader)
    names = {topics.COMMAND_ARM: (rerun.arm_names, "arm"), topics.COMMAND_HAND: (rerun.effector_names, "hand")}
    episodes = [e for e in rerun.episodes if e.stop_ns is not None]
    stops = [asked.get(e.index, e.stop_ns) for e in episodes]
    judged, world_s = {}, 0.0
    for column in ("recorded", "rerun"):
        sides = [commands(rerun.commands[topic], joint_names, column, wire[kind])
                 for topic, (joint_names, kind) in names.items() if topic in rerun.commands]
        judged[column], seconds = play(effector, rate_hz, scenes, sides, stops)
        world_s += seconds
    plays = []
    for e, stop in zip(episodes, stops):
        mine, theirs = judged["recorded"].get(stop), judged["rerun"].get(stop)
        plays.append(EpisodePlay(e.index, e.task, e.judged, e.judged_reason,
                                 mine.mark if mine else None, mine.reason if mine else "",
                                 theirs.mark if theirs else None, theirs.reason if theirs else ""))
    return PhysicsPlay(plays, world_s, time.perf_counter() - started)


def print_physics(console, report: dict) -> None:
    """Per session that was played: each episode's outcome as recorded, replayed and re-computed."""
    from rich.markup import escape
    from rich.table import Table

    for s in report["sessions"]:
        p = s.get("physics")
        if not p:
            continue
        table = Table(title=f"{Path(s['session']).name}: outcomes in the physics world", title_justify="left")
        for column in ("episode", "task", "recorded", "recorded commands", "re-computed commands", "why (re-computed)"):
            table.add_column(column)
        for e in p["episodes"]:
            style = "red" if e["regressed"] else "" if e["agree"] else "yellow"
            table.add_row(str(e["episode"]), e["task"], e["recorded"] or "-", e["replayed"] or "-",
                          e["recomputed"] or "-", escape(e["recomputed_reason"]), style=style)
        console.print(table)
        x = p["world_s"] / p["wall_s"] if p["wall_s"] else 0.0
        console.print(f"played {p['world_s']:.1f} s of world time in {p['wall_s']:.1f} s ({x:.1f}x real time); "
                      + ("the recorded commands give every recorded mark" if p["agree"] else
                         "[yellow]the recorded commands do not give every recorded mark[/]"), highlight=False)
