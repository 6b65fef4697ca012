"""One-DoF end effectors driven by one finger (TelePreview appendix E).

A parallel-jaw gripper opens and closes with the flexion of one chosen SMPL-X finger joint; a vacuum
gripper switches on and off at thresholds on that same angle, with hysteresis so that a finger hovering
near the threshold does not make it chatter.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class GripperMap:
    """Opening (metres) = fully open at zero flexion, closed at `closed_flexion`, linear in between."""

    max_opening: float
    closed_flexion: float

    def __call__(self, flexion: float) -> float:
        closed = min(max(flexion / self.closed_flexion, 0.0), 1.0)
        return self.max_opening * (1.0 - closed)


@dataclass(frozen=True)
class VacuumMap:
    """On above `on_flexion`, off below `off_flexion`, unchanged in between."""

    on_flexion: float
    off_flexion: float

    def __post_init__(self):
        if self.off_flexion >= self.on_flexion:
            raise ValueError(
                f"vacuum off threshold {self.off_flexion} must be below the on threshold {self.on_flexion}"
            )

    def __call__(self, flexion: float, was_on: bool) -> bool:
        if flexion >= self.on_flexion:
            return True
        if flexion <= self.off_flexion:
            return False
        return was_on
