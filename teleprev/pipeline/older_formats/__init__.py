"""Older session formats: what computed their sessions, kept so that `teleprev eval` re-runs them bit for bit.

    format 1   commands made by each step under the speed caps alone; numpy arithmetic
    format 2   commands made by each step under the motion limits (StepMotion); numpy arithmetic
    format 3   as format 2, with the compiled kernels (the current arithmetic)
    format 4   the paced sender samples the commands from the steps' targets (teleprev/pipeline/planner.py),
               as now
    format 5   the glove read flexion first (formats 1 to 4 read it abduction first), as now
    format 6   a hand command that is not free holds back only the fingers whose motion would collide,
               where formats 1 to 5 braked the whole hand; after input loss the planner resumes at the
               engage fraction, where formats 4 and 5 resumed at full speed
    format 7   an engage from rest starts the arm from the last command while its controller holds it,
               where formats up to 6 started it from the measured arm
    format 8   was never recorded
    format 9   where the whole hand brakes and its segment is not free with the clearance, it brakes
               keeping its direction, else on into the margin if no link collides on the way, where
               formats 1 to 8 stopped short; a hand joint keeps its braking envelope towards the joint
               limit ahead, where formats 1 to 8 kept it in the target's frame only
    format 10  the planner lowers the arm's speed fraction so that the flange keeps its linear speed cap,
               where formats 4 to 9 left it uncapped
    (format 11, the current one: the planner plans the arm at [pipeline] arm_plan_fraction of its
    acceleration and jerk limits, a stream's first ticks at half that jerk, where formats up to 10
    planned at the limits throughout)

    numpy_arithmetic   NumpyArmIK, NumpyArmRetargeter, NumpySweptCheck, NumpyCorrector (formats 1 and 2)
    abduction_first    AbductionFirstPipeline: the compiled glove reading of formats 3 and 4
    stopping_short     StoppingShortSweptCheck: the hand stops short where braking is not free with the
                       clearance (formats 1 to 8)
    target_frame_limiter  TargetFrameHandLimiter: the hand's braking envelope in the target's frame only
                       (formats 1 to 8)
    braking_swept      BrakingSweptCheck: the whole hand brakes where a command is not free (formats 1 to 5)
    uncapped_tcp       UncappedTcpPipeline, whose planner leaves the flange's speed uncapped (formats 4 to 9)
    measured_engage    MeasuredEngagePipeline, whose planner engages the arm from its measured state
                       (formats 4 to 6)
    immediate_resume   ImmediateResumePipeline, whose planner resumes at full speed after input loss
                       (formats 4 and 5)
    step_motion        StepMotion: the commands of a step under the motion limits, and idle steps
    step_commands      StepCommandsPipeline (formats 2 and 3), NumpyPipeline (formats 1 and 2, numpy's
                       glove reading): the current step's targets, then the step's own commands
    step_driver        StepCommandsDriver: records the steps' commands, runs the idle steps

`arithmetic(format)` is the one place where a format number chooses its classes (teleprev/assembly.py
asks it for every format older than topics.FORMAT_VERSION). Each class subclasses the current one.
"""

from __future__ import annotations

from dataclasses import replace

from teleprev.pipeline.arithmetic import Arithmetic
from teleprev.pipeline.older_formats.abduction_first import AbductionFirstPipeline
from teleprev.pipeline.older_formats.braking_swept import BrakingSweptCheck
from teleprev.pipeline.older_formats.immediate_resume import ImmediateResumePipeline, ImmediateResumePlanner
from teleprev.pipeline.older_formats.measured_engage import MeasuredEngagePipeline, MeasuredEngagePlanner
from teleprev.pipeline.older_formats.numpy_arithmetic import (
    NumpyArmIK,
    NumpyArmRetargeter,
    NumpyCorrector,
    NumpySweptCheck,
)
from teleprev.pipeline.older_formats.step_commands import (
    NumpyPipeline,
    StepCommandsPipeline,
    StepCommandsResult,
    StepCommandsState,
)
from teleprev.pipeline.older_formats.step_driver import StepCommandsDriver
from teleprev.pipeline.older_formats.step_motion import MotionState, StepMotion
from teleprev.pipeline.older_formats.stopping_short import StoppingShortSweptCheck
from teleprev.pipeline.older_formats.target_frame_limiter import TargetFrameHandLimiter
from teleprev.pipeline.older_formats.uncapped_tcp import UncappedTcpPipeline, UncappedTcpPlanner

# Format 2: commands go through the motion limits; idle steps may command between trigger samples; a
# ModeSwitch with reason "estop" stops commanding at once.
MOTION_FORMAT_VERSION = 2
# Format 3: the pipeline's arithmetic is the compiled hot path (IK, CPN/CCN, hand preparation, swept
# check), whose last bits differ from the numpy code that recorded formats 1 and 2.
COMPILED_FORMAT_VERSION = 3
# Format 4: the commands are sampled by the paced sender at the instant it sends them, from the pipeline
# steps' targets (teleprev/pipeline/planner.py); /command/tick records which targets each tick had.
PLANNED_FORMAT_VERSION = 4
# Format 5: the glove is read flexion first (teleprev/human/smplx.py).
FLEXION_FIRST_FORMAT_VERSION = 5
# Format 6: a hand command that is not free slides the fingers that would collide; after input loss the
# planner resumes at the engage fraction.
SLIDING_FORMAT_VERSION = 6
# Format 7: an engage from rest starts the arm from the command its controller still holds.
HELD_ENGAGE_FORMAT_VERSION = 7
# Format 8 was never recorded.
# Format 9: a braking hand keeps its direction, or brakes into the clearance margin, where it stopped short.
BRAKING_IN_MARGIN_FORMAT_VERSION = 9
# Format 10: the planner keeps the flange within its linear speed cap.
TCP_CAPPED_FORMAT_VERSION = 10

__all__ = ["MOTION_FORMAT_VERSION", "COMPILED_FORMAT_VERSION", "PLANNED_FORMAT_VERSION", "FLEXION_FIRST_FORMAT_VERSION",
           "SLIDING_FORMAT_VERSION", "HELD_ENGAGE_FORMAT_VERSION", "BRAKING_IN_MARGIN_FORMAT_VERSION",
           "TCP_CAPPED_FORMAT_VERSION", "arithmetic",
           "AbductionFirstPipeline",
           "BrakingSweptCheck", "ImmediateResumePipeline", "ImmediateResumePlanner", "MeasuredEngagePipeline",
           "MeasuredEngagePlanner", "MotionState", "NumpyArmIK",
           "NumpyArmRetargeter", "NumpyCorrector", "NumpyPipeline", "NumpySweptCheck", "StepCommandsDriver",
           "StepCommandsPipeline", "StepCommandsResult", "StepCommandsState", "StepMotion", "StoppingShortSweptCheck",
           "TargetFrameHandLimiter", "UncappedTcpPipeline", "UncappedTcpPlanner"]


def arithmetic(session_format: int) -> Arithmetic:
    """The classes sessions of an older `session_format` were computed with: each planned the arm at its
    acceleration and jerk limits (format 11 plans below them)."""
    return replace(_classes(session_format), plans_below_limits=False)


def _classes(session_format: int) -> Arithmetic:
    if session_format >= TCP_CAPPED_FORMAT_VERSION:
        return Arithmetic()
    if session_format >= BRAKING_IN_MARGIN_FORMAT_VERSION:
        return Arithmetic(pipeline=UncappedTcpPipeline)
    if session_format >= HELD_ENGAGE_FORMAT_VERSION:
        return Arithmetic(swept_check=StoppingShortSweptCheck, hand_limiter=TargetFrameHandLimiter,
                          pipeline=UncappedTcpPipeline)
    if session_format >= SLIDING_FORMAT_VERSION:
        return Arithmetic(swept_check=StoppingShortSweptCheck, hand_limiter=TargetFrameHandLimiter,
                          pipeline=MeasuredEngagePipeline)
    if session_format >= FLEXION_FIRST_FORMAT_VERSION:
        return Arithmetic(swept_check=BrakingSweptCheck, hand_limiter=TargetFrameHandLimiter,
                          pipeline=ImmediateResumePipeline)
    if session_format >= PLANNED_FORMAT_VERSION:
        return Arithmetic(swept_check=BrakingSweptCheck, hand_limiter=TargetFrameHandLimiter,
                          pipeline=AbductionFirstPipeline)
    motion = session_format >= MOTION_FORMAT_VERSION
    if session_format >= COMPILED_FORMAT_VERSION:
        return Arithmetic(motion, swept_check=BrakingSweptCheck, hand_limiter=TargetFrameHandLimiter,
                          pipeline=StepCommandsPipeline, driver=StepCommandsDriver)
    return Arithmetic(motion, NumpyArmIK, NumpyArmRetargeter, NumpySweptCheck, TargetFrameHandLimiter,
                      NumpyCorrector, NumpyPipeline, StepCommandsDriver)
