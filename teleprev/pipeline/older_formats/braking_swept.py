"""Formats up to 5 braked the whole hand where a command's swept check found it not free (Motion._avoid:
brake, else stop short); the current format holds back only the fingers whose motion would collide and
slides them (SweptCheck.slide). Where even braking was not free, they stopped short, as formats up to 8 did."""

from __future__ import annotations

from teleprev.pipeline.older_formats.stopping_short import StoppingShortSweptCheck


class BrakingSweptCheck(StoppingShortSweptCheck):
    slides = False
