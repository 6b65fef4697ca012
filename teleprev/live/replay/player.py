"""Playing a session's commands back: on screen, to the simulated robot, or to a real one.

The sequence played is the recorded commands (or, for a session recorded in preview only, the previewed
targets). It goes through the same guards as live commands, in the recording's own time: a sequence
that was valid when recorded passes unchanged, anything else is stepped within the caps. Played X
times faster, every step would be X times faster, so the speed is capped at the largest multiple that
keeps every joint under its speed limit; the values sent never depend on the speed.

With a robot attached, playback starts in preview (the robot receives nothing); engaging first ramps
the robot from where it is to the first command at a fraction of the caps, then plays.
"""

from __future__ import annotations

import copy
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from teleprev import topics
from teleprev.errors import ConfigError, DeviceError, SessionError
from teleprev.messages import JointSample
from teleprev.pipeline.bimanual import side_topic
from teleprev.pipeline.derivatives import RESUME_GAP_NS, divided_differences, runs
from teleprev.pipeline.guard import JointGuard
from teleprev.pipeline.trajectory import JointMotion
from teleprev.session.reader import SessionReader


@dataclass
class Playback:
    t_ns: np.ndarray  # recorded step times
    arm: np.ndarray  # (N, arm joints)
    effector: np.ndarray  # (N, effector joints)
    arm_names: tuple[str, ...]
    effector_names: tuple[str, ...]
    source: str  # "commands" or "targets"
    adjusted: int = 0  # steps the guards had to change
    arm_sent: np.ndarray | None = None  # per step: was the arm commanded then (None: at every step)
    effector_sent: np.ndarray | None = None

    def sent(self, side: str) -> np.ndarray:
        """Boolean per step: the steps at which this side ("arm" or "effector") gets a command."""
        mask = self.arm_sent if side == "arm" else self.effector_sent
        return np.ones(len(self.t_ns), dtype=bool) if mask is None else mask


def _stream(reader: SessionReader, topic: str, lo: int, hi: int) -> tuple[dict[int, np.ndarray], tuple[str, ...]]:
    values, names = {}, ()
    if topic in reader.topics:
        for msg in reader.messages(topics=[topic], start_ns=lo, end_ns=hi):
            values[msg.payload.stamp_ns] = msg.payload.positions
            names = msg.payload.names
    return values, names


def load_playback(path, episode: int | None = None, side: str = "") -> Playback:
    """A session's commands (else its previewed targets); `side`: one side's of a bimanual session
    (/command/left/arm ...)."""
    with SessionReader(path) as reader:
        return _playback(reader, path, episode, side)


def load_dataset_playback(root, episode: int | None, limits: dict, side: str = "") -> Playback:
    """One episode of a LeRobot dataset's `action` column (any dataset's) as commands at its frames'
    timestamps, its joints matched to the rig's by name as `teleprev audit DATASET` matches them; `side`:
    one side's columns of a bimanual dataset (left_arm.joint1 ...), `limits` being that side's."""
    from teleprev.export.actions import read_actions

    data = read_actions(root, limits, side)
    present = np.unique(data.episodes)
    if episode is None:
        raise ConfigError("a dataset is replayed one episode at a time: pass --episode N", str(root))
    if episode not in present:
        have = f"episodes {present.min()}..{present.max()}" if len(present) else "no episodes"
        raise SessionError(f"no episode {episode} in this dataset ({have})", str(root))
    t, q = data.episode(episode)
    if len(t) < 2:
        raise SessionError(f"episode {episode} has {len(t)} frame: nothing to play", str(root))
    return Playback(t, q[:, data.arm_cols], q[:, data.hand_cols], tuple(limits["arm"]["names"]),
                    tuple(limits["hand"]["names"]), "dataset actions")


def _playback(reader: SessionReader, path, episode: int | None, side: str = "") -> Playback:
    def topic(name: str) -> str:
        return side_topic(name, side) if side else name

    lo, hi = 0, 1 << 63
    if episode is not None:
        eps = {e.index: e for e in reader.episodes()}
        if episode not in eps:
            raise SessionError(f"no episode {episode} (episodes: {sorted(eps) or 'none'})", str(path))
        lo, hi = eps[episode].start_ns, eps[episode].stop_ns or hi
    arm, arm_names = _stream(reader, topic(topics.COMMAND_ARM), lo, hi)
    eff, eff_names = _stream(reader, topic(topics.COMMAND_HAND), lo, hi)
    source = "commands"
    if not arm:
        arm, arm_names = _stream(reader, topic(topics.ARM_TARGET), lo, hi)
        eff, eff_names = _stream(reader, topic(topics.CORRECTED), lo, hi)
        source = "targets"
    if not arm or not eff:
        whose = f"the {side} side's " if side else ""
        raise SessionError(f"nothing to play: the session holds no {whose}arm and end-effector commands or targets",
                           str(path))
    stamps = sorted(set(arm) | set(eff))
    first_arm = arm[min(arm)]
    first_eff = eff[min(eff)]
    a, e, last_a, last_e = [], [], first_arm, first_eff
    for s in stamps:  # hold the other stream's last value where only one was commanded at a step
        last_a, last_e = arm.get(s, last_a), eff.get(s, last_e)
        a.append(last_a)
        e.append(last_e)
    # Each side is sent at its own recorded stamps only: a held value at the other side's stamps would be
    # a stop-and-go that no robot should follow.
    return Playback(
        np.array(stamps, dtype=np.int64),
        np.array(a),
        np.array(e),
        tuple(arm_names),
        tuple(eff_names),
        source,
        arm_sent=np.array([s in arm for s in stamps]),
        effector_sent=np.array([s in eff for s in stamps]),
    )


def validate(p: Playback, arm_guard: JointGuard, effector_guard: JointGuard) -> Playback:
    """The sequence as the guards pass it in the recording's time (unchanged when it was valid), each side
    over its own commands (a step between them is as long as it was when recorded)."""
    out, adjusted = {}, np.zeros(len(p.t_ns), dtype=bool)
    for side, q, guard in (("arm", p.arm, arm_guard), ("effector", p.effector, effector_guard)):
        # A recorded step may span up to a resume gap (a late step the generator planned over); the live
        # guard's shorter max_dt is for unsteady input, not for commands that were sent.
        guard = copy.copy(guard)
        guard.max_dt = max(guard.max_dt, RESUME_GAP_NS / 1e9)
        q_out, sent = q.copy(), p.sent(side)
        last = None
        for k in range(len(p.t_ns)):
            if sent[k] and last is not None:
                dt = (p.t_ns[k] - p.t_ns[last]) / 1e9
                if side == "arm":
                    q_out[k] = guard.step(q_out[last], q[k], dt)
                else:
                    q_out[k] = guard.step(q_out[last], q[k], dt, target_valid=guard.valid(q[k]))
                adjusted[k] |= not np.array_equal(q_out[k], q[k])
            elif not sent[k] and last is not None:
                q_out[k] = q_out[last]  # held where this side was not commanded (shown, not sent)
            if sent[k]:
                last = k
        out[side] = q_out
    return Playback(p.t_ns, out["arm"], out["effector"], p.arm_names, p.effector_names, p.source, int(adjusted.sum()),
                    p.arm_sent, p.effector_sent)


def safe_speed(p: Playback, arm_caps: np.ndarray, effector_caps: np.ndarray, requested: float,
               motion=None) -> float:
    """The largest speed up to `requested` at which no step exceeds a joint's speed cap in wall time, and
    (with the pipeline's Motion) no acceleration or jerk exceeds the generator's limits: played X times
    faster, speeds scale by X, accelerations by X^2 and jerks by X^3."""
    if len(p.t_ns) < 2:
        return requested
    dt = np.diff(p.t_ns) / 1e9
    ratios = []
    for q, caps in ((p.arm, arm_caps), (p.effector, effector_caps)):
        step = np.abs(np.diff(q, axis=0))
        with np.errstate(divide="ignore", invalid="ignore"):
            r = caps[None, :] * dt[:, None] / step  # speed multiple each step allows
        ratios.append(np.nanmin(np.where(np.isfinite(r), r, np.inf)) if step.size else np.inf)
    if motion is not None:
        for side, q, sent in (("arm", p.arm, p.sent("arm")), ("hand", p.effector, p.sent("effector"))):
            t, q = p.t_ns[sent], q[sent]
            pieces = runs(t, RESUME_GAP_NS)
            if len(pieces) > 1:  # played faster, a pause between runs must stay a pause (the arm stood there)
                ratios.append(min(int(t[r.start] - t[r.start - 1]) for r in pieces[1:]) / RESUME_GAP_NS)
            for run in pieces:  # each run starts from rest: measured alone
                _, acc, jerk = divided_differences(t[run], q[run])
                if side == "arm":  # against the limits, not the fraction of them the planner plans at
                    planned = motion.plan_fraction
                    ratios += [_power_room(motion.arm.acceleration / planned, acc, 2),
                               _power_room(motion.arm.jerk / planned, jerk, 3)]
                elif motion.hand is not None:
                    ratios.append(_power_room(motion.hand.acceleration, acc, 2))
    speed = float(min(requested, *ratios))
    return min(requested, 1.0) if requested >= 1.0 and speed >= 1.0 - ROUNDING else speed


ROUNDING = 1e-6  # a recording at its limits measures 1 +- rounding: that is 1x


def _power_room(limit: np.ndarray, measured: np.ndarray, power: int) -> float:
    """The speed multiple X at which measured * X**power stays within the limit."""
    peak = np.abs(measured).max(axis=0) if measured.size else np.zeros_like(limit)
    with np.errstate(divide="ignore"):
        room = (np.asarray(limit) / peak) ** (1.0 / power)
    return float(np.min(np.where(peak > 0, room, np.inf)))


class _Generated:
    """Commands as the pipeline's Motion generates them, one step at a time: the arm jerk-limited, the hand
    acceleration-capped along segments that keep the clearance (an end effector without a cap through its
    speed guard, as live)."""

    def __init__(self, motion, effector_guard: JointGuard, arm: np.ndarray, effector: np.ndarray):
        self.motion, self.effector_guard = motion, effector_guard
        self.arm = JointMotion.rest(arm)
        self.effector, self.effector_v = np.array(effector, dtype=float), np.zeros(len(effector))
        self.dt_before, self.flags = 0.0, []

    def step(self, dt: float, arm, arm_v, effector, effector_v, frac: float = 1.0) -> None:
        m = self.motion
        self.arm = m.arm.track_inside(self.arm, arm, arm_v, dt, frac)  # braking for the joint limits as live
        if m.hand is not None:
            self.effector, self.effector_v = m.hand_step(self.effector, self.effector_v, effector, effector_v, dt,
                                                         self.dt_before, frac, self.flags)
        else:
            self.effector = self.effector_guard.step(self.effector, effector, dt, frac, target_valid=True)
        self.dt_before = dt

    def at_rest_on(self, arm: np.ndarray, effector: np.ndarray) -> bool:
        return (self.arm.at_rest and not np.any(self.effector_v) and np.max(np.abs(self.arm.q - arm)) < 1e-9
                and np.max(np.abs(self.effector - effector)) < 1e-9)


def smooth(
    p: Playback, motion, effector_guard: JointGuard, speed: float = 1.0, max_step_s: float = 1 / 120
) -> Playback:
    """The played sequence as the pipeline's own generator would command it (`replay --smooth`), in the
    time it is played at `speed`: from rest at the first command, meeting each recorded command as a
    moving target (at most `max_step_s` apart, so no pause is long enough for a servo arm to stand),
    braking to rest at the last. Stamps stay in the recording's time (played time x speed), as the
    Player expects."""
    g = _Generated(motion, effector_guard, p.arm[0], p.effector[0])
    t0 = int(p.t_ns[0])
    t, arm, eff = [t0], [g.arm.q], [g.effector]
    played_ns = 0

    def step(until_ns, *targets):
        # Each step lasts a whole number of nanoseconds and is generated for exactly that: the stamps' divided
        # differences then measure the generator's own motion, within its limits (not 1e-5 past them).
        nonlocal played_ns
        g.step((until_ns - played_ns) / 1e9, *targets)
        played_ns = until_ns
        t.append(t0 + int(round(played_ns * speed)))
        arm.append(g.arm.q)
        eff.append(g.effector)

    arm_sent, eff_sent = p.sent("arm"), p.sent("effector")
    for k in range(1, len(p.t_ns)):
        end_ns = int(round((int(p.t_ns[k]) - t0) / speed))  # played time of this command
        span_ns = end_ns - played_ns
        if span_ns <= 0:
            continue
        span = span_ns / 1e9
        va = (p.arm[k] - p.arm[k - 1]) / span if arm_sent[k] and arm_sent[k - 1] else None
        ve = (p.effector[k] - p.effector[k - 1]) / span if eff_sent[k] and eff_sent[k - 1] else None
        n = max(1, int(np.ceil(span / max_step_s - 1e-9)))
        start_ns = played_ns
        for i in range(1, n + 1):
            # where the recorded command stream (linear between commands) is at this sub-step
            f = i / n
            step(start_ns + int(round(span_ns * f)), p.arm[k - 1] + f * (p.arm[k] - p.arm[k - 1]), va,
                 p.effector[k - 1] + f * (p.effector[k] - p.effector[k - 1]), ve)
    settle_ns = int(round(max_step_s * 1e9))
    for _ in range(int(SETTLE_S / max_step_s)):  # then come to rest on the last command
        if g.at_rest_on(p.arm[-1], p.effector[-1]):
            break
        step(played_ns + settle_ns, p.arm[-1], None, p.effector[-1], None)
    return Playback(np.array(t, dtype=np.int64), np.array(arm), np.array(eff), p.arm_names, p.effector_names,
                    f"{p.source}, smoothed", len(t))


SETTLE_S = 30.0  # the longest a smoothed sequence may take to come to rest after its last command


class StartTogether:
    """The players of a bimanual replay: each, at rest on its first command, waits for the others before it
    plays (so the two sides play the recorded instants together); one that cannot get there (stopped, a robot
    that reports no state) cancels the start for all."""

    def __init__(self, players: int):
        self.players, self.arrived, self.cancelled = players, 0, False
        self._cv = threading.Condition()

    def arrive_and_wait(self, stopped, hold, period_s: float) -> bool:
        """Here; then `hold()` (the first command sent again: a servo's stream does not pause) every period
        until all are here (True), or one cancels or `stopped()` (False)."""
        with self._cv:
            self.arrived += 1
            self._cv.notify_all()
        while True:
            with self._cv:
                if self.cancelled or self.arrived >= self.players:
                    return not self.cancelled
                if stopped():
                    self.cancelled = True
                    self._cv.notify_all()
                    return False
                self._cv.wait(period_s)
            hold()

    def cancel(self) -> None:
        with self._cv:
            self.cancelled = True
            self._cv.notify_all()


@dataclass
class PlayerState:
    mode: str = "preview"  # preview | ramp | playing | done
    index: int = 0
    sent: list[tuple[str, str, np.ndarray]] = field(default_factory=list)  # (phase, kind, command) in send order
    message: str = ""
    start_ns: int | None = None  # the clock's instant of the first played step, once playing (its commands' stamps)


class Player:
    """Sends a validated Playback to actuators ("arm", "hand") at `speed`; `measured()` gives the robot's
    current (arm, effector) joints for the engage ramp."""

    def __init__(
        self,
        playback: Playback,
        speed: float,
        actuators: dict,
        arm_guard: JointGuard,
        effector_guard: JointGuard,
        measured=None,
        engage_speed_frac: float = 0.5,
        rate_hz: float = 120.0,
        motion=None,
        clock=None,
        lead_s: float = 0.0,
        together: StartTogether | None = None,
        t0_ns: int | None = None,
    ):
        """`lead_s`: hand each played command over this long before its stamp (actuators in processes of
        their own write each at its stamp: the player's thread then sets no command's timing); `together`: the
        players of a bimanual replay, each past its ramp, start playing at once; `t0_ns`: the recorded instant
        played first (default the playback's first step), theirs in common."""
        self.p = playback
        self.lead_s = lead_s
        self.together = together
        self.t0_ns = int(playback.t_ns[0]) if t0_ns is None else t0_ns
        self.motion = motion  # teleprev.pipeline.motion.Motion: the engage ramp keeps its limits
        self.clock = clock  # stamps the commands with the time they are sent (a robot runs them then)
        self.speed = speed
        self.actuators = actuators
        self.arm_guard, self.effector_guard = arm_guard, effector_guard
        self.measured = measured
        self.engage_speed_frac = engage_speed_frac
        self.period = 1.0 / rate_hz
        self.connect_timeout_s = 10.0
        self.state = PlayerState()
        self._engage = threading.Event()
        self._stop = threading.Event()

    def engage(self) -> None:
        self._engage.set()

    def stop(self) -> None:
        self._stop.set()

    def _now_ns(self) -> int:
        return self.clock.now_ns() if self.clock is not None else time.perf_counter_ns()

    def _send(self, arm: np.ndarray, eff: np.ndarray, t_ns: int, to_arm: bool = True, to_hand: bool = True) -> None:
        for kind, names, q, due in (
            ("arm", self.p.arm_names, arm, to_arm),
            ("hand", self.p.effector_names, eff, to_hand),
        ):
            if not due:
                continue
            device = self.actuators.get(kind)
            if device is not None:
                try:
                    device.send(JointSample(t_ns, names, q))
                except DeviceError as e:  # a controller fault, an unplugged robot: stop playing, say why
                    self.state.message = str(e)
                    self._stop.set()
                    return
            self.state.sent.append((self.state.mode, kind, q))

    def run(self) -> PlayerState:
        """Preview until engaged (or stopped), ramp, then play; returns what was sent."""
        while not self._engage.wait(0.05):
            if self._stop.is_set():
                self.state.mode = "done"
                return self.state
        if self.actuators and not self._ramp():
            self.state.mode = "done"
            if self.together is not None:
                self.together.cancel()  # the other side does not play alone
            return self.state
        if self.together is not None and not self.together.arrive_and_wait(
                self._stop.is_set, lambda: self._send(self.p.arm[0], self.p.effector[0], self._now_ns()),
                self.period):
            self.state.mode = "done"
            return self.state
        self.state.mode = "playing"
        start, t0 = time.perf_counter(), self.t0_ns
        start_ns = self._now_ns() + int(self.period * 1e9)
        self.state.start_ns = start_ns
        arm_sent, eff_sent = self.p.sent("arm"), self.p.sent("effector")
        for k in range(len(self.p.t_ns)):
            if self._stop.is_set():
                break
            due = (self.p.t_ns[k] - t0) / 1e9 / self.speed
            time.sleep(max(0.0, due - self.lead_s - (time.perf_counter() - start)))
            self.state.index = k
            # stamped with when it is meant to run at this speed: what the robot's timing will be
            self._send(self.p.arm[k], self.p.effector[k], start_ns + int(round(due * 1e9)), arm_sent[k], eff_sent[k])
        if self.lead_s and not self._stop.is_set():  # the last commands handed over go out at their stamps
            self._stop.wait(self.lead_s + 2 * self.period)
        self.state.mode = "done"
        return self.state

    def _ramp(self) -> bool:
        """Move from the robot's measured joints to the first command; False if the robot never reported."""
        self.state.mode = "ramp"
        measured, deadline = None, time.perf_counter() + self.connect_timeout_s
        while measured is None and not self._stop.is_set():
            measured = self.measured() if self.measured else (self.p.arm[0], self.p.effector[0])
            if measured is None:
                if time.perf_counter() > deadline:
                    self.state.message = "the robot reports no state: not moving it"
                    return False
                time.sleep(0.02)
        if measured is None:
            return False
        arm, eff = measured
        arm = np.clip(arm, self.arm_guard.lower, self.arm_guard.upper)
        target_a, target_e = self.p.arm[0], self.p.effector[0]
        if self.motion is not None:
            return self._limited_ramp(arm, eff, target_a, target_e)
        t_ns = self._now_ns()
        while not self._stop.is_set():
            if np.max(np.abs(arm - target_a)) < 1e-9 and np.max(np.abs(eff - target_e)) < 1e-9:
                return True
            arm = self.arm_guard.step(arm, target_a, self.period, self.engage_speed_frac)
            eff = self.effector_guard.step(eff, target_e, self.period, self.engage_speed_frac, target_valid=True)
            t_ns += int(self.period * 1e9)
            self._send(arm, eff, t_ns)
            time.sleep(self.period)
        return False

    def _limited_ramp(self, arm, eff, target_a, target_e) -> bool:
        """The ramp through the pipeline's generator: from rest where the robot is to rest at the first
        command, at the engage fraction of the speed caps and within the acceleration and jerk limits."""
        g, t_ns = _Generated(self.motion, self.effector_guard, arm, eff), self._now_ns()
        step_ns = int(round(self.period * 1e9))  # generated for the whole nanoseconds its stamps are apart
        while not self._stop.is_set():  # at least one command: the robot holds where it is told to
            g.step(step_ns / 1e9, target_a, None, target_e, None, self.engage_speed_frac)
            t_ns += step_ns
            self._send(g.arm.q, g.effector, t_ns)
            time.sleep(self.period)
            if g.at_rest_on(target_a, target_e):
                return True  # at rest on the first command: the played commands start from rest there
        return False
