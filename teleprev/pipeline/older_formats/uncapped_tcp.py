"""Formats up to 9: the planner let the flange move as fast as the joints' speed caps took it (1.18 m/s seen,
where a servo-mode xArm faults past 1.0 m/s, error C60); the current format lowers the arm's speed fraction
to keep it within the cap (CommandPlanner.caps_tcp_speed, teleprev/pipeline/tcp_speed.py). The pipeline
names its planner for `CommandPlanner.for_pipeline`, so that eval re-runs the ticks with it."""

from __future__ import annotations

from teleprev.pipeline.planner import CommandPlanner
from teleprev.pipeline.step import Pipeline


class UncappedTcpPlanner(CommandPlanner):
    caps_tcp_speed = False


class UncappedTcpPipeline(Pipeline):
    planner = UncappedTcpPlanner
