"""The simulated operator: a deterministic (seeded) person performing the paper's five tasks.

For a time t (seconds since the operator started) it gives the right hand's finger angles (flexion and
abduction of the 15 SMPL-X hand joints; `hand_pose` turns them into the glove's axis-angle pose) and the
right wrist pose in the suit's world frame: metres, z up, the operator standing at the origin facing +x,
the resting wrist 0.30 m in front, 0.15 m to the right and 1.00 m up, palm facing left, thumb up, fingers
forward and tilted 20 degrees down. Its hand frame is SMPL-X's (fingers -x, palm -y, thumb +z).

Episodes repeat one after another, each one task's script (devices/sim/tasks.py), ending at rest and a
short pause. Every transition is a minimum-jerk move (zero velocity and acceleration at both ends); on
top a person's physiological tremor (8-12 Hz, a fraction of a millimetre) and slow sway. Repetitions
differ in layout, speed (0.85-1.2x), grasp tightness and angles, drawn from (seed, episode number).

Phase scripts (grasp shapes in devices/sim/grasps.py; c = tightness):
    pick_place    reach+pre-shape beside the cup, approach (down beside it, then in), grasp power(c),
                  lift (squeezing: c+0.25..0.45), move, place, release (relax), retreat (up, then
                  off and open), return, pause
    hang          reach palm-down+pre-shape, approach, pinch(c), lift (firmer pinch c+0.3), move to the
                  peg, hang (roll), lower, release, retreat, return, pause
    pour          pick as above (lower, pour_grip: index and thumb off the mouth), move over the bowl
                  turning the hand towards it, fingers down (grip firm: 0.9..1), pour (pronate ~120 deg),
                  shake twice, upright, move back turning the hand back, then place it as pick_place does
    box_rotation  reach palm-down over the box, approach, claw grip, twist about the box's centre, release,
                  lift; watching, align over the box and twist again (up to 4 times) until it has turned a
                  quarter turn; retreat, return, pause
    cup_stack     two picks (power grasps) each placed onto the third cup, then return, pause
Power grasps tighter than c ~ 0.65, pinches tighter than ~0.75 and flat hands squeezed past ~0.55
retarget into LEAP self-collision (fingertips in the palm, thumb across the fingers, index over middle);
every task squeezes that far while carrying or pushing (lift/move/place, pour/shake, hang, push) and
is collision-free while reaching, pre-shaping, returning and pausing.

The task follows `set_task`: the current phase finishes, the hand returns to rest, and the next episode
is the new task. A session calls `on_episode_task` at every episode start (DeviceContext.task_listeners):
a fresh episode of its task begins that way (at once when resting), and the operator rests after it until
the session's next episode, so that its episodes are the session's. A session's episode that ends before
the operator's does not start the next one late: the start that finds it under way sends the hand back to
rest, and the operator rests until the session's next episode start (the physics world lays out no new
scene during a session's episode; the session's first start, finding the operator in an episode of its
own, begins the fresh one at once from where the hand is). On a physics rig the operator rests from the
start until the session's first episode (`wait_for_session`). `mode="fixed"` ignores both and
`mode="cycle"` goes through the five tasks in turn.

Watching (`watch`, on a physics rig): phases that aim (tasks.Phase.aim) are laid out as they begin, to
where the operator sees the objects and the robot's hand then, as a person at the table corrects a reach
for a cup that is not quite where it was; blind, they go where the script planned.
"""

from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass
from typing import Literal

import numpy as np

from teleprev.devices import ConfigError, smplx, transforms
from teleprev_devices.sim import grasps
from teleprev_devices.sim.tasks import SCRIPTS, TASKS, SceneObject, Script

REST_WRIST = np.array([0.30, -0.15, 1.00])
# Palm left (+y), thumb up (+z), fingers forward (+x), as columns of the SMPL-X hand frame's axes
# (fingers -x, palm -y, thumb +z), then tilted 20 degrees down about the world y axis.
REST_ROTATION = transforms.rpy_to_matrix(0.0, np.deg2rad(20.0), 0.0) @ np.diag([-1.0, -1.0, 1.0])
_KEEP_EPISODES = 6


def min_jerk(s: np.ndarray | float) -> np.ndarray | float:
    """0 -> 1 with zero velocity and acceleration at both ends."""
    return s * s * s * (10.0 + s * (-15.0 + 6.0 * s))


@dataclass(frozen=True)
class OperatorState:
    t: float
    episode: int
    task: str
    phase: str
    wrist_position: np.ndarray  # (3,) suit frame, metres
    wrist_rotation: np.ndarray  # (3, 3)
    flexion: np.ndarray  # (15,)
    abduction: np.ndarray  # (15,)

    @property
    def wrist_quaternion(self) -> np.ndarray:
        return transforms.matrix_to_quat(self.wrist_rotation)

    @property
    def hand_pose(self) -> np.ndarray:
        return smplx.hand_pose_from_angles(self.flexion, self.abduction)


class _Track:
    """Knots (time, value) joined by minimum-jerk segments; equal neighbouring values hold."""

    def __init__(self, t0: float, value: np.ndarray):
        self.times = [t0]
        self.values = [np.array(value, dtype=float)]

    def move(self, start: float, end: float, target: np.ndarray) -> None:
        start = max(start, self.times[-1])
        end = max(end, start)
        if start > self.times[-1]:
            self.times.append(start)
            self.values.append(self.values[-1])
        self.times.append(end)
        self.values.append(np.array(target, dtype=float))

    def hold_until(self, t: float) -> None:
        if t > self.times[-1]:
            self.times.append(t)
            self.values.append(self.values[-1])

    def __call__(self, t: float) -> np.ndarray:
        times = self.times
        if t <= times[0]:
            return self.values[0]
        if t >= times[-1]:
            return self.values[-1]
        i = bisect.bisect_right(times, t) - 1
        t0, t1 = times[i], times[i + 1]
        a, b = self.values[i], self.values[i + 1]
        if t1 <= t0:
            return b
        return a + (b - a) * min_jerk((t - t0) / (t1 - t0))

    def truncate(self, t: float) -> None:
        """Drop everything after t, which must be a knot time (the track is at rest there)."""
        keep = bisect.bisect_right(self.times, t)
        value = self(t)
        del self.times[keep:], self.values[keep:]
        if self.times[-1] < t:
            self.times.append(t)
            self.values.append(value)


@dataclass
class _Episode:
    index: int
    task: str
    script: Script
    start: float
    end: float
    phase_starts: list[float]
    phase_names: list[str]
    wrist: _Track  # (6,): position (task frame), roll pitch yaw
    hand: _Track  # (30,)
    built: int = 0  # phases laid out on the tracks so far (they are laid out as they begin: _build)
    cut: bool = False  # ended early by set_task
    paced: bool = False  # begun at a session's episode start (on_episode_task)


class _Tremor:
    """A person's involuntary motion: sums of sines (physiological tremor and slow sway), smooth."""

    def __init__(self, rng: np.random.Generator, dims: int, tremor: float, sway: float):
        freq = np.concatenate([rng.uniform(8.0, 12.0, (dims, 2)), rng.uniform(0.15, 0.6, (dims, 2))], axis=1)
        self.omega = 2 * np.pi * freq
        self.amp = np.concatenate(
            [rng.uniform(0.5, 1.0, (dims, 2)) * tremor / 2, rng.uniform(0.5, 1.0, (dims, 2)) * sway / 2], axis=1
        )
        self.phase = rng.uniform(0.0, 2 * np.pi, (dims, 4))

    def __call__(self, t: float) -> np.ndarray:
        return (self.amp * np.sin(self.omega * t + self.phase)).sum(axis=1)


class SimOperator:
    """A seeded simulated person. Times are seconds since the operator started (see `time_s`)."""

    def __init__(self, seed: int = 0, task: str = "pick_place", mode: Literal["follow", "fixed", "cycle"] = "follow",
                 origin_ns: int = 0, clock=None):
        if task not in SCRIPTS:
            raise ValueError(f"unknown task {task!r} (tasks: {', '.join(TASKS)})")
        if mode not in ("follow", "fixed", "cycle"):
            raise ValueError(f"unknown mode {mode!r} (follow, fixed or cycle)")
        self.seed = seed
        self.mode = mode
        self.origin_ns = origin_ns
        self._clock = clock
        self._task = task
        self._lock = threading.RLock()
        # Paced by a session's episodes (on_episode_task): the index of the last episode allowed to begin,
        # resting after it until the next is asked for; None: one episode after another
        self._allowed: int | None = None
        self._eyes = None  # what the operator sees (see watch)
        self._looking = False
        self._hold: np.ndarray | None = None  # a calibration pose held instead of the task (see hold)
        rng = np.random.default_rng([seed, 0x5EED])
        self._wrist_tremor = _Tremor(rng, 3, tremor=0.0006, sway=0.006)
        self._rot_tremor = _Tremor(rng, 3, tremor=0.004, sway=0.02)
        self._finger_tremor = _Tremor(rng, 30, tremor=0.008, sway=0.03)
        self._episodes: list[_Episode] = []
        self._next_index = 0
        self._append_episode(0.0, np.concatenate([np.zeros(3), np.zeros(3)]), grasps.rest(0.2))

    # ---- time ----------------------------------------------------------------------------------
    def time_s(self, session_ns: int) -> float:
        return (session_ns - self.origin_ns) / 1e9

    def _now_s(self) -> float:
        return 0.0 if self._clock is None else self.time_s(self._clock.now_ns())

    # ---- the timeline --------------------------------------------------------------------------
    def _next_task(self) -> str:
        if self.mode == "cycle":
            return TASKS[self._next_index % len(TASKS)]
        return self._task

    def _append_episode(self, start: float, wrist0: np.ndarray, hand0: np.ndarray) -> None:
        index = self._next_index
        task = self._next_task()
        self._next_index += 1
        rng = np.random.default_rng([self.seed, index])
        rest = rng.normal(0.0, 0.006, 3).clip(-0.015, 0.015)
        script = SCRIPTS[task](rng, rest)
        phase_starts = list(np.cumsum([start] + [ph.duration for ph in script.phases[:-1]]))
        end = start + sum(ph.duration for ph in script.phases)
        self._episodes.append(_Episode(index, task, script, start, end, phase_starts,
                                       [p.name for p in script.phases], _Track(start, wrist0), _Track(start, hand0),
                                       paced=self._allowed is not None))
        del self._episodes[:-_KEEP_EPISODES]

    def _build(self, ep: _Episode, t: float) -> None:
        """Lay the episode's tracks out up to the phases begun by t. A phase that aims (Phase.aim) looks at
        the world as it begins: where the operator sees the objects and the robot's hand then (`watch`)
        moves its target; without eyes it goes where the script planned."""
        phases = ep.script.phases
        if self._looking:  # asked again while looking (eyes that ask the operator): the phases wait
            return
        while ep.built < len(phases) and not ep.cut and ep.phase_starts[ep.built] <= t:
            ph, start = phases[ep.built], ep.phase_starts[ep.built]
            wrist, hand = ep.wrist, ep.hand
            position, rpy = ph.position, ph.rpy
            if ph.aim is not None and self._eyes is not None:
                self._looking = True
                try:
                    seen = self._eyes()
                finally:
                    self._looking = False
                if seen is not None:  # nothing seen yet: as planned
                    aimed = ph.aim(seen, wrist(start)[:3], position)
                    position, rpy = (aimed, rpy) if len(aimed) == 3 else (aimed[:3], aimed[3:])
            if position is not None or rpy is not None:
                current = wrist.values[-1]
                target = np.concatenate([
                    current[:3] if position is None else position,
                    current[3:] if rpy is None else rpy,
                ])
                wrist.move(start + ph.wrist_window[0] * ph.duration, start + ph.wrist_window[1] * ph.duration, target)
            if ph.hand is not None:
                hand.move(start + ph.hand_window[0] * ph.duration, start + ph.hand_window[1] * ph.duration, ph.hand)
            wrist.hold_until(start + ph.duration)
            hand.hold_until(start + ph.duration)
            ep.built += 1

    def _episode(self, t: float) -> _Episode:
        with self._lock:
            while t >= self._episodes[-1].end and (self._allowed is None or self._next_index <= self._allowed):
                last = self._episodes[-1]
                self._build(last, last.end)
                self._append_episode(last.end, last.wrist.values[-1], last.hand.values[-1])
            for ep in reversed(self._episodes):
                if t >= ep.start:
                    self._build(ep, t)
                    return ep
            return self._episodes[0]  # older than what is kept: the earliest state we have

    def set_task(self, name: str, anew: bool = False) -> bool:
        """Switch to another task: the current phase ends, the hand returns to rest, then the new task's
        episodes follow. `anew`: the same task too, a fresh episode of it begun that way (at once when
        resting), as a session's episode starts. Returns False (and changes nothing) when the task is fixed
        or cycling."""
        if name not in SCRIPTS:
            raise ValueError(f"unknown task {name!r} (tasks: {', '.join(TASKS)})")
        if self.mode != "follow":
            return False
        with self._lock:
            if name == self._task and not anew:
                return True
            self._task = name
            now = self._now_s()
            ep = self._episode(now)
            resting = now >= (ep.end if ep.cut else ep.phase_starts[-1])  # back at rest (its pause or after)
            if anew and ep.cut and ep.task == name and not resting:  # already ending (a start a moment ago)
                return True
            del self._episodes[self._episodes.index(ep) + 1:]  # what follows is made again, as the new task
            self._next_index = ep.index + 1
            if self._allowed is not None:
                self._allowed = self._paced_next(ep, resting, anew)
            if anew and ep.cut and resting:  # returned from a cut and resting: the new one begins now
                ep.wrist.hold_until(now)
                ep.hand.hold_until(now)
                ep.end = max(ep.end, now)
                return True
            if anew and self._allowed is not None and not ep.paced and not ep.cut:
                # The session's first start finds the operator in an episode of its own: the session's begins
                # at once, from where the hand is, so that the world lays its scene out as the session's episode
                # starts rather than seconds into it (after a return to rest).
                ep.wrist.truncate(now)
                ep.hand.truncate(now)
                keep = max(1, sum(1 for s in ep.phase_starts if s < now))
                ep.phase_starts, ep.phase_names = ep.phase_starts[:keep], ep.phase_names[:keep]
                ep.end, ep.cut = now, True
                return True
            if (ep.task == name and not anew) or ep.cut:
                return True
            # Cut at the end of the current phase, where both hand and wrist are at rest.
            cut = next((s for s in ep.phase_starts if s >= now), ep.end)
            self._build(ep, cut)
            pause_start = ep.phase_starts[-1]  # already resting in the pause: end the episode here
            if now >= pause_start:
                cut = max(now, pause_start)
            ep.wrist.truncate(cut)
            ep.hand.truncate(cut)
            keep = sum(1 for s in ep.phase_starts if s < cut)
            ep.phase_starts, ep.phase_names = ep.phase_starts[:keep], ep.phase_names[:keep]
            if cut < pause_start:
                ep.phase_starts.append(cut)
                ep.phase_names.append("return")
                ep.wrist.move(cut, cut + 1.1, np.zeros(6))
                ep.hand.move(cut, cut + 0.9, grasps.rest(0.2))
                cut += 1.6
                ep.wrist.hold_until(cut)
                ep.hand.hold_until(cut)
            ep.end = cut
            ep.cut = True
            return True

    def _paced_next(self, ep: _Episode, resting: bool, anew: bool) -> int:
        """Paced by the session: the index of the last episode allowed to begin after `ep`, the one that a
        task switch (or a session's episode start, `anew`) finds under way. At rest, the next begins now; in the
        middle of the operator's own (the session's first start) at once, from where the hand is; in the middle of a
        session's episode (a session episode shorter than the task), none: the operator returns to rest and
        rests until the session's next episode start, so that no scene of its own begins during the session's
        episode (the world's mark at the episode's stop judges the scene the episode ran in)."""
        if anew and ep.paced and not resting:
            return ep.index
        return ep.index + 1

    def wait_for_session(self) -> None:
        """Paced by a session from the start (a physics rig): rest until its first episode starts, so that the
        robot, engaged as that episode begins, is engaged on a hand at rest, as a person waits for the cue."""
        with self._lock:
            ep = self._episodes[-1]
            ep.wrist.truncate(ep.start)
            ep.hand.truncate(ep.start)
            ep.phase_starts, ep.phase_names = ep.phase_starts[:1], ep.phase_names[:1]
            ep.end, ep.cut, ep.paced = ep.start, True, True
            self._allowed = ep.index

    def on_episode_task(self, name: str) -> None:
        """The session's episode-start hook (DeviceContext.task_listeners): a fresh episode of the episode's
        task when its label is one of the five, and from the first such start on, rest after each episode
        until the session's next one (so that the operator's episodes are the session's: the physics world
        lays each one's scene out as it begins); "calibration:<pose>" holds a calibration pose (open, fist,
        neutral) until "calibration:done"; any other label leaves the operator at what it is doing."""
        if name in SCRIPTS:
            with self._lock:
                if self._allowed is None:  # from now on an episode begins only when the session's does
                    self._allowed = self._next_index - 1
            self.set_task(name, anew=True)
        elif name.startswith("calibration:"):
            self.hold(name.split(":", 1)[1])

    def hold(self, pose: str) -> None:
        """Hold a calibration pose with the wrist at rest: "open" (flat hand), "fist", "neutral" (the
        relaxed hand); "done" goes back to the task."""
        shapes = {"open": grasps.flat(0.0), "fist": grasps.fist(1.0), "neutral": grasps.rest()}
        with self._lock:
            self._hold = None if pose == "done" else shapes.get(pose, self._hold)

    @property
    def task(self) -> str:
        """The task being performed now."""
        return self._episode(self._now_s()).task

    # ---- what the person does at time t --------------------------------------------------------
    def state(self, t: float) -> OperatorState:
        ep = self._episode(t)
        with self._lock:
            w = ep.wrist(t) if self._hold is None else np.zeros(6)
            h = ep.hand(t) if self._hold is None else self._hold
            phase_i = bisect.bisect_right(ep.phase_starts, t) - 1
            phase = ep.phase_names[max(phase_i, 0)]
        position = REST_WRIST + w[:3] + self._wrist_tremor(t)
        rpy = w[3:] + self._rot_tremor(t)
        rotation = transforms.rpy_to_matrix(*rpy) @ REST_ROTATION
        angles = h + self._finger_tremor(t)
        return OperatorState(t, ep.index, ep.task, phase, position, rotation, angles[:15], angles[15:])

    def hand_angles(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Flexion and abduction (15,) each; the glove's fast path (no wrist)."""
        ep = self._episode(t)
        with self._lock:
            h = ep.hand(t) if self._hold is None else self._hold
        angles = h + self._finger_tremor(t)
        return angles[:15], angles[15:]

    def hand_pose(self, t: float) -> np.ndarray:
        """The SMPL-X right hand pose (15, 3), axis-angle."""
        return self.state(t).hand_pose

    def wrist(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Right wrist position (3,) and orientation quaternion (x y z w) in the suit frame."""
        s = self.state(t)
        return s.wrist_position, s.wrist_quaternion

    def objects(self, t: float) -> tuple[SceneObject, ...]:
        """The scene of the episode at t, in the task frame (metres from the resting wrist)."""
        return self._episode(t).script.objects

    def episode(self, t: float) -> tuple[int, str]:
        ep = self._episode(t)
        return ep.index, ep.task

    def episode_span(self, index: int) -> tuple[float, float]:
        """Start and end (seconds) of episode `index` (made up to it where not yet made)."""
        with self._lock:
            while self._episodes[-1].index < index:
                last = self._episodes[-1]
                self._build(last, last.end)
                self._append_episode(last.end, last.wrist.values[-1], last.hand.values[-1])
            ep = next(e for e in self._episodes if e.index == index)
            return ep.start, ep.end

    def watch(self, eyes) -> None:
        """Look at the world while acting: `eyes()` gives each object's and the robot hand's ("hand")
        position (task frame) and yaw now, or None when it has seen nothing yet."""
        self._eyes = eyes

    def spots(self, t: float) -> dict[str, tuple[float, float, float]]:
        """Where the episode at t put its objects (task frame x, y and yaw), for the physics world's layout."""
        return dict(self._episode(t).script.spots)


def task_mode(task_setting: str) -> tuple[str, str]:
    """(initial task, mode) from a device's `task` setting: "" follows set_task, "cycle" goes through
    all five, a task name fixes it."""
    if task_setting == "":
        return "pick_place", "follow"
    if task_setting == "cycle":
        return TASKS[0], "cycle"
    if task_setting in SCRIPTS:
        return task_setting, "fixed"
    raise ValueError(f"task must be '', 'cycle' or one of {', '.join(TASKS)}; got {task_setting!r}")


def shared_operator(context, device: str, seed: int, task_setting: str) -> SimOperator:
    """The rig's one operator, so that glove and suit stream the same person. Created by the first sim
    device that asks; a second device asking for another seed or task is a configuration error."""
    from teleprev_devices.sim.shared import get_or_create

    task, mode = task_mode(task_setting)

    def create():
        op = SimOperator(seed, task, mode, origin_ns=context.clock.start_ns, clock=context.clock)
        op.created_by = (device, seed, task_setting)
        listeners = getattr(context, "task_listeners", None)
        if listeners is not None:
            listeners.append(op.on_episode_task)  # the session sets the task at every episode start
            if mode == "follow" and getattr(context, "physics", None) is not None:
                op.wait_for_session()  # the world lays out each session episode's scene as it starts
        return op

    op = get_or_create(context.shared, "sim.operator", create)
    first, first_seed, first_task = op.created_by
    if (first_seed, first_task) != (seed, task_setting):
        raise ConfigError(
            f"the sim operator is shared: seed={seed}, task={task_setting!r} here but seed={first_seed}, "
            f"task={first_task!r} in [devices.{first}]; give both devices the same seed and task",
            f"[devices.{device}]",
        )
    return op
