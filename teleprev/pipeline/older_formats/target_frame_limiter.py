"""Formats up to 8 braked a hand joint only in its target's frame: a target met moving, short of a joint
limit, could be followed faster than the joint could stop before the limit, where the command was then held
(past the acceleration cap). The current format keeps the same braking envelope towards the limit ahead
(HandLimiter.brakes_for_limits)."""

from __future__ import annotations

from teleprev.pipeline.trajectory import HandLimiter


class TargetFrameHandLimiter(HandLimiter):
    brakes_for_limits = False
