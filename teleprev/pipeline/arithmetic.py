"""The classes a pipeline computes with, chosen by the session format it computes as.

The current format's are the defaults: live recording builds those. `teleprev eval` re-runs an older
session with its own format's (teleprev/pipeline/older_formats), so that it reproduces bit for bit;
teleprev/assembly.py builds a pipeline from either.
"""

from __future__ import annotations

from dataclasses import dataclass

from teleprev.pipeline.driver import PipelineDriver
from teleprev.pipeline.step import Pipeline
from teleprev.pipeline.swept import SweptCheck
from teleprev.pipeline.trajectory import HandLimiter
from teleprev.retarget.arm import ArmRetargeter
from teleprev.robot.ik import ArmIK


@dataclass(frozen=True)
class Arithmetic:
    motion: bool = True  # acceleration and jerk limits on the commands (False: the speed caps alone)
    arm_ik: type = ArmIK
    arm_retargeter: type = ArmRetargeter
    swept_check: type = SweptCheck
    hand_limiter: type = HandLimiter
    corrector: type | None = None  # None: noncollision.corrector.Corrector (loaded for the rigs that have one)
    pipeline: type = Pipeline
    driver: type = PipelineDriver  # what feeds the pipeline its samples
    plans_below_limits: bool = True  # the arm at [pipeline] arm_plan_fraction of its accel and jerk (<= 10: at them)
