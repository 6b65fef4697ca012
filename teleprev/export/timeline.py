"""Frame times of an episode and which sample of every stream each frame uses. Pure numpy on stamps.

LeRobot frames are evenly spaced: frame k stands for grid time g_k = g_0 + k / fps, with g_0 the
reference camera's first frame in the episode (the episode's start without a camera).

- Reference camera: frame k shows the camera frame nearest to g_k if it lies within half a period
  (and was not used already); the frame's time t_k is then that camera frame's time, so state and
  image describe the same instant. Otherwise the camera dropped a frame: the last image is held and
  t_k = g_k; a hold older than `max_gap` is a gap.
- Observations (state, other cameras, extras): the latest sample at or before t_k, never a later one;
  older than `max_gap` is a gap.
- Derived actions ("next"): the latest sample at or before t_{k+1}, the state the robot reached.
- Actions: the commanded trajectory at the frame's grid time g_k (the dataset's own timestamp): between
  the commands sent before and after it (interpolated by the exporter: `Lookup.next` and `frac`), where
  they are at most `max_gap` apart; after the last command, that command while it is not older than
  `max_gap` (the robot keeps its last target); else a gap.
- Sent actions (timing "sent", the raw command stream): the first command at or after t_k and before the
  next frame's time (the command sent after the observation, as lerobot's record loop pairs them); if
  none was sent in that window, the last one before t_k while it is not older than `max_gap`.

The alignment error of a frame is the distance between t_k and the samples it uses. Frames where some
stream has a gap are left out: at the ends of an episode they are trimmed, inside they split it.
All times are int64 nanoseconds on the session clock (the samples' stamp_ns).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_NS = 1_000_000_000


@dataclass(frozen=True)
class Lookup:
    """For every frame: the index of the sample used (-1: none), its distance to the frame's time,
    and whether the stream covers the frame (no gap). A trajectory lookup also gives the sample after
    (`next`, -1: none: the sample itself holds) and how far between the two the frame's time lies."""

    index: np.ndarray
    err_ns: np.ndarray
    ok: np.ndarray
    next: np.ndarray | None = None
    frac: np.ndarray | None = None


@dataclass(frozen=True)
class Frames:
    grid_ns: np.ndarray  # g_k
    time_ns: np.ndarray  # t_k
    fresh: np.ndarray  # the reference camera delivered a new frame for k (all True without camera)
    camera: Lookup | None  # the reference camera's frame per k; err: |camera time - g_k| or the hold's age


@dataclass(frozen=True)
class Gap:
    """Frames [first, stop) that some streams do not cover; `streams` names them."""

    first: int
    stop: int
    streams: tuple[str, ...]
    at_edge: bool  # at the start or end of the episode (trimmed, not a split)


@dataclass
class EpisodePlan:
    frames: Frames
    lookups: dict[str, Lookup]  # per stream name, the reference camera included
    pieces: list[tuple[int, int]]  # [first, stop) frame ranges that become LeRobot episodes
    gaps: list[Gap] = field(default_factory=list)
    short: list[tuple[int, int]] = field(default_factory=list)  # pieces left out as too short

    def covered(self) -> np.ndarray:
        ok = np.ones(len(self.frames.time_ns), dtype=bool)
        for look in self.lookups.values():
            ok &= look.ok
        return ok


def frame_grid(ref: np.ndarray | None, start_ns: int, stop_ns: int, fps: int, max_gap_ns: int) -> Frames:
    """The frames of an episode [start_ns, stop_ns): from the reference camera's frame stamps `ref`
    (sorted), or a fixed clock when `ref` is None."""
    if ref is None:
        n = max(0, -(-(stop_ns - start_ns) * fps // _NS))
        grid = start_ns + (np.arange(n, dtype=np.int64) * _NS) // fps
        return Frames(grid, grid.copy(), np.ones(n, dtype=bool), None)
    all_ref = np.asarray(ref, dtype=np.int64)
    lo, hi = np.searchsorted(all_ref, [start_ns, stop_ns], side="left")
    ref = all_ref[lo:hi]  # the episode's camera frames
    if len(ref) == 0:
        empty = np.zeros(0, dtype=np.int64)
        return Frames(empty, empty, np.zeros(0, dtype=bool), Lookup(empty, empty, np.zeros(0, dtype=bool)))
    g0, last = int(ref[0]), int(ref[-1])
    n = (2 * (last - g0) * fps + _NS) // (2 * _NS) + 1  # grid points up to half a period after the last frame
    grid = g0 + (np.arange(n, dtype=np.int64) * _NS) // fps
    j = np.searchsorted(ref, grid, side="left")
    prev = np.clip(j - 1, 0, len(ref) - 1)
    nxt = np.clip(j, 0, len(ref) - 1)
    take_prev = (j == len(ref)) | ((j > 0) & (grid - ref[prev] <= ref[nxt] - grid))
    nearest = np.where(take_prev, prev, nxt)
    dist = np.abs(ref[nearest] - grid)
    close = 2 * dist * fps <= _NS
    repeat = np.zeros(n, dtype=bool)
    repeat[1:] = (nearest[1:] == nearest[:-1]) & close[:-1]
    fresh = close & ~repeat
    last_fresh = np.maximum.accumulate(np.where(fresh, np.arange(n), -1))
    image = nearest[np.maximum(last_fresh, 0)]
    age = grid - ref[image]
    time = np.where(fresh, ref[nearest], grid)
    err = np.where(fresh, dist, age)
    ok = fresh | ((last_fresh >= 0) & (age <= max_gap_ns))
    return Frames(grid, time, fresh, Lookup(image + lo, err, ok))


def observe(stamps: np.ndarray, times: np.ndarray, max_gap_ns: int) -> Lookup:
    """The latest sample at or before each time (never a later one)."""
    i = np.searchsorted(stamps, times, side="right") - 1
    has = i >= 0
    err = np.where(has, times - stamps[np.maximum(i, 0)], 0) if len(stamps) else np.zeros(len(times), dtype=np.int64)
    return Lookup(i, err, has & (err <= max_gap_ns))


def act(stamps: np.ndarray, times: np.ndarray, fps: int, max_gap_ns: int) -> Lookup:
    """The first command in [t_k, t_{k+1}) (t_k + one period for the last frame); else the last one
    before t_k while it is at most max_gap old."""
    n = len(stamps)
    if n == 0:
        zeros = np.zeros(len(times), dtype=np.int64)
        return Lookup(zeros - 1, zeros, np.zeros(len(times), dtype=bool))
    until = next_times(times, fps)
    j = np.searchsorted(stamps, times, side="left")
    jc = np.minimum(j, n - 1)
    after = (j < n) & (stamps[jc] < until)
    before = j - 1
    bc = np.maximum(before, 0)
    held_ok = (before >= 0) & (times - stamps[bc] <= max_gap_ns)
    index = np.where(after, jc, np.where(before >= 0, before, -1))
    err = np.where(after, stamps[jc] - times, np.where(before >= 0, times - stamps[bc], 0))
    return Lookup(index, err, after | held_ok)


def trajectory(stamps: np.ndarray, times: np.ndarray, max_gap_ns: int) -> Lookup:
    """The commanded trajectory at each time: between the commands at or before and after it, where they
    are at most max_gap apart; after the last one, that one while it is at most max_gap old."""
    n = len(stamps)
    if n == 0:
        zeros = np.zeros(len(times), dtype=np.int64)
        return Lookup(zeros - 1, zeros, np.zeros(len(times), dtype=bool), zeros - 1, np.zeros(len(times)))
    i = np.searchsorted(stamps, times, side="right") - 1
    has = i >= 0
    ic = np.maximum(i, 0)
    j = np.minimum(ic + 1, n - 1)
    span = stamps[j] - stamps[ic]
    between = has & (i + 1 < n) & (span <= max_gap_ns) & (span > 0)
    age = np.where(has, times - stamps[ic], 0)
    frac = np.where(between, age / np.where(span > 0, span, 1), 0.0)
    err = np.where(between, np.minimum(age, stamps[j] - times), age)
    ok = between | (has & (age <= max_gap_ns))  # else: the last command held while it is not too old
    return Lookup(i, err, ok, np.where(between, j, -1), frac)


def next_times(times: np.ndarray, fps: int) -> np.ndarray:
    """Each frame's next frame time (the last frame's: one period later)."""
    out = np.empty_like(times)
    out[:-1] = times[1:]
    if len(times):
        out[-1] = times[-1] + _NS // fps
    return out


def plan_episode(
    ref_name: str | None,
    ref: np.ndarray | None,
    streams: dict[str, tuple[np.ndarray, bool]],
    start_ns: int,
    stop_ns: int,
    fps: int,
    max_gap_ns: int,
    min_frames: int,
) -> EpisodePlan:
    """Frames, lookups, gaps and pieces of one episode. `streams` maps a name to (sorted stamps,
    timing): False an observation, "trajectory" an action (the commanded trajectory at the frame's grid
    time), True (or "sent") the first command sent in the frame, "next" the observation at the next
    frame's time; the reference camera is `ref_name` with stamps `ref` (None: fixed clock)."""
    frames = frame_grid(ref, start_ns, stop_ns, fps, max_gap_ns)
    lookups: dict[str, Lookup] = {}
    if ref_name is not None and frames.camera is not None:
        lookups[ref_name] = frames.camera
    for name, (stamps, timing) in streams.items():
        stamps = np.asarray(stamps, dtype=np.int64)
        if timing == "next":
            lookups[name] = observe(stamps, next_times(frames.time_ns, fps), max_gap_ns)
        elif timing == "trajectory":
            lookups[name] = trajectory(stamps, frames.grid_ns, max_gap_ns)
        elif timing:
            lookups[name] = act(stamps, frames.time_ns, fps, max_gap_ns)
        else:
            lookups[name] = observe(stamps, frames.time_ns, max_gap_ns)
    plan = EpisodePlan(frames, lookups, [])
    ok = plan.covered()
    n = len(ok)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    runs = list(zip(edges[::2].tolist(), edges[1::2].tolist()))  # covered [first, stop)
    bad = []
    cursor = 0
    for first, stop in runs:
        if first > cursor:
            bad.append((cursor, first))
        cursor = stop
    if cursor < n:
        bad.append((cursor, n))
    for first, stop in bad:
        missing = tuple(name for name, look in lookups.items() if not look.ok[first:stop].all())
        plan.gaps.append(Gap(first, stop, missing, first == 0 or stop == n))
    for first, stop in runs:
        (plan.pieces if stop - first >= min_frames else plan.short).append((first, stop))
    return plan


def piece_errors(plan: EpisodePlan, first: int, stop: int, names: list[str]) -> float:
    """The worst alignment error (ns) of `names` over frames [first, stop)."""
    worst = 0
    for name in names:
        look = plan.lookups[name]
        if stop > first:
            worst = max(worst, int(look.err_ns[first:stop].max()))
    return float(worst)
