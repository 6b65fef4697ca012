"""The commands of a re-run session beside the recorded ones, on their own stamps.

The paced sender samples the commands at its ticks (teleprev/pipeline/planner.py); the pipelines of older
session formats made them at their steps, stamped with the step's time (teleprev/pipeline/older_formats).
A CommandTrack holds one command stream either way: the stamps of the recorded commands and of the re-run
ones (the union), and both values at each (NaN where one side has none).

A session's ticks are replayed: each recorded CommandTick names the last pipeline update its tick had
adopted, so a planner that adopts the re-run's updates up to it, at each recorded tick's instant, samples
the same commands bit for bit when the pipeline is the one that recorded them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.pipeline.planner import CommandPlanner, ModeUpdate, TargetUpdate


@dataclass
class CommandTrack:
    t_ns: np.ndarray  # (N,) int64, sorted
    rerun: np.ndarray  # (N, joints), NaN rows where the re-run sent nothing at t
    recorded: np.ndarray  # (N, joints), NaN rows where the recording has nothing at t

    def select(self, lo: int, hi: int) -> CommandTrack:
        rows = (self.t_ns >= lo) & (self.t_ns < hi)
        return CommandTrack(self.t_ns[rows], self.rerun[rows], self.recorded[rows])

    def same(self) -> bool:
        """Re-run and recorded are equal bit for bit (NaN matching NaN)."""
        a, b = self.rerun, self.recorded
        return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


def track(rerun: dict[int, np.ndarray], recorded: dict[int, np.ndarray], width: int) -> CommandTrack:
    """A CommandTrack from {stamp: values} of each side."""
    stamps = np.array(sorted(set(rerun) | set(recorded)), dtype=np.int64)
    out_rerun = np.full((len(stamps), width), np.nan)
    out_recorded = np.full((len(stamps), width), np.nan)
    for i, s in enumerate(stamps.tolist()):
        if s in rerun:
            out_rerun[i] = rerun[s]
        if s in recorded:
            out_recorded[i] = recorded[s]
    return CommandTrack(stamps, out_rerun, out_recorded)


@dataclass(frozen=True)
class RecordedTick:
    t_ns: int
    seq: int


def replay_ticks(planner: CommandPlanner, updates: list[TargetUpdate | ModeUpdate],
                 ticks: list[RecordedTick]) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """The commands a planner samples at the recorded ticks, adopting the updates each tick had: ({stamp:
    arm command}, {stamp: end-effector command})."""
    arm: dict[int, np.ndarray] = {}
    hand: dict[int, np.ndarray] = {}
    k = 0
    for t in sorted(ticks, key=lambda x: x.t_ns):
        while k < len(updates) and updates[k].seq <= t.seq:
            planner.adopt(updates[k])
            k += 1
        sent = planner.tick(t.t_ns)
        if sent is None:
            continue
        if sent.arm is not None:
            arm[sent.t_ns] = sent.arm
        if sent.hand is not None:
            hand[sent.t_ns] = sent.hand
    return arm, hand
