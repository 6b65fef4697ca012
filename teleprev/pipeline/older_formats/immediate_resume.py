"""Formats 4 and 5: after ticks without targets (stale, missing or invalid input) the planner went back to
the targets at full speed; the current format resumes at the engage fraction (CommandPlanner.resumes_slowly).
The pipeline names its planner for `CommandPlanner.for_pipeline`, so that eval re-runs the ticks with it."""

from __future__ import annotations

from teleprev.pipeline.planner import CommandPlanner
from teleprev.pipeline.step import Pipeline


class ImmediateResumePlanner(CommandPlanner):
    resumes_slowly = False


class ImmediateResumePipeline(Pipeline):
    planner = ImmediateResumePlanner
