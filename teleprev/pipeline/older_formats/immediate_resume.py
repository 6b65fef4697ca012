"""Formats 4 and 5: after ticks without targets (stale, missing or invalid input) the planner went back to
the targets at full speed; the current format resumes at the engage fraction (CommandPlanner.resumes_slowly).
Like format 6, they engaged the arm from its measured state (measured_engage). The pipeline names its
planner for `CommandPlanner.for_pipeline`, so that eval re-runs the ticks with it."""

from __future__ import annotations

from teleprev.pipeline.older_formats.measured_engage import MeasuredEngagePipeline, MeasuredEngagePlanner


class ImmediateResumePlanner(MeasuredEngagePlanner):
    resumes_slowly = False


class ImmediateResumePipeline(MeasuredEngagePipeline):
    planner = ImmediateResumePlanner
