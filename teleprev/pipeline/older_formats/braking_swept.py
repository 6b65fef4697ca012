"""Formats up to 5 braked the whole hand where a command's swept check found it not free (Motion._avoid:
brake, else stop short); the current format holds back only the fingers whose motion would collide and
slides them (SweptCheck.slide)."""

from __future__ import annotations

from teleprev.pipeline.swept import SweptCheck


class BrakingSweptCheck(SweptCheck):
    slides = False
