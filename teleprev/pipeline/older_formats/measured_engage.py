"""Formats up to 6: every engage from rest started the arm's commands at its measured state; the current
format starts them from the last command while the arm's controller still holds it
(CommandPlanner.engages_from_held: contact may push a held arm a little off it, and a servo-mode
controller takes the new stream to start where it holds, so the first command read as a jerk). The
pipeline names its planner (which, as up to format 9, leaves the flange's speed uncapped: uncapped_tcp) for
`CommandPlanner.for_pipeline`, so that eval re-runs the ticks with it."""

from __future__ import annotations

from teleprev.pipeline.older_formats.uncapped_tcp import UncappedTcpPipeline, UncappedTcpPlanner


class MeasuredEngagePlanner(UncappedTcpPlanner):
    engages_from_held = False


class MeasuredEngagePipeline(UncappedTcpPipeline):
    planner = MeasuredEngagePlanner
