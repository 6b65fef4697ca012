"""What a live session shows the operator: the session loop's snapshot and one line per device.

The live session fills them (teleprev/live/core/loop.py replaces its snapshot after every change); the
terminal preview (teleprev/preview/dashboard.py) and the XR page's status draw them. They sit below both,
so that the preview never imports the live session.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class SideView:
    """One side of a bimanual rig as the preview draws it: that side's last step and measured joints."""

    side: str
    step: Any = None  # the side's last StepResult
    measured_arm: np.ndarray | None = None
    measured_effector: np.ndarray | None = None


@dataclass(frozen=True)
class LoopSnapshot:
    """What the terminal preview shows; replaced as a whole by the loop thread."""

    mode: str = "preview"
    episode: int = -1
    episode_active: bool = False
    task: str = ""
    episode_started_ns: int = 0
    session_started_ns: int = 0
    step: Any = None  # the last StepResult (teleprev/pipeline/step.py)
    measured_arm: np.ndarray | None = None
    measured_effector: np.ndarray | None = None
    message: str = ""  # the last refusal or warning, for the operator
    commands_sent: int = 0
    dropped: int = 0
    fault: str = ""  # why the session stays in preview until the operator engages
    camera: Any = None  # the latest ImageSample of the first camera heard from, for the preview
    depth: Any = None  # the latest DepthSample of the first depth camera heard from, for the preview
    input_age_ms: float = 0.0  # how old the sample the last step took was then (session clock - its stamp)
    stale_ms: float = 0.0  # the pipeline's stale limit: input older than this holds the last command (0: none)
    sides: tuple[SideView, ...] = ()  # a bimanual rig's sides, left first (the fields above: the right side's)

    @property
    def input_old(self) -> bool:
        """The last step's input was old: a third of the stale limit or more (a busy machine, a slow link)."""
        return self.stale_ms > 0 and self.input_age_ms >= self.stale_ms * OLD_INPUT_FRAC


OLD_INPUT_FRAC = 1 / 3  # of the stale limit: 50 ms at 150, the age issue 42 holds a glove's samples to


@dataclass(frozen=True)
class DeviceRow:
    """One line of the terminal preview's device table: a device's runner stats and the loop's drops for it."""

    name: str
    kind: str
    state: str  # ok | gap | error | connecting
    rate_hz: float
    nominal_hz: float
    latency_ms: float
    dropped: int  # samples the session loop's queue had no room for
    lost: int  # samples the device's runner could not hand to the loop (the sink raised)
    errors: int
    lost_input: int = 0  # input lost before the device read it (socket overruns, sequence gaps, its queue)
    hint: str = ""  # what the operator has to do for it to stream (e.g. open the XR page's URL), or ""
