"""A bimanual export against an export of one side's streams alone (tests/bimanual, bench/bimanual.py)."""

from __future__ import annotations

import numpy as np


def within(part: np.ndarray, whole: np.ndarray, ends: int = 2) -> bool:
    """`part` equals `whole` but for up to `ends` frames more at either end of `whole`: a side alone may keep a
    frame more than both sides together, whose episode ends where the first of their streams does (its
    commands stop a tick before the other's)."""
    extra = whole.shape[0] - part.shape[0]
    return 0 <= extra <= 2 * ends and any(np.array_equal(part, whole[o:o + part.shape[0]])
                                          for o in range(min(extra, ends) + 1))
