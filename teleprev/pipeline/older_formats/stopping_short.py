"""Formats up to 8 stopped the hand short on its braking segment wherever that segment was not free with
the clearance (Motion._avoid's last resort, which breaks the acceleration cap); the current format then
brakes keeping the hand's direction, else on into the margin where no link collides on the way
(SweptCheck.brakes_in_margin)."""

from __future__ import annotations

from teleprev.pipeline.swept import SweptCheck


class StoppingShortSweptCheck(SweptCheck):
    brakes_in_margin = False
