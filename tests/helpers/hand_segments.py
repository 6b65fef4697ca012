"""Random joint-space segments of a hand, of every kind a swept check meets (tests/pipeline/test_swept.py,
bench/swept.py)."""

import numpy as np


def random_segments(hand, n: int, rng) -> list[tuple[np.ndarray, np.ndarray]]:
    """Zero-length, short, medium and long segments, from anywhere: clear starts, starts inside the margin,
    colliding starts (uniform samples are mostly not clear)."""
    pool = hand.sample_uniform(2 * n, rng)
    out = []
    for k in range(n):
        q0, q1 = pool[2 * k], pool[2 * k + 1]
        kind = k % 6
        if kind == 0:
            q1 = q0.copy()
        elif kind == 1:
            q1 = q0 + rng.normal(0, 0.01, q0.shape)
        elif kind == 2:
            q1 = q0 + 0.05 * (q1 - q0)
        elif kind == 3:
            q1 = q0 + 0.3 * (q1 - q0)
        elif kind == 4:  # from near the open hand, which is clear
            q0 = hand.neutral() + rng.normal(0, 0.05, q0.shape)
            q1 = q0 + rng.normal(0, 0.05, q0.shape)
        out.append((q0, np.clip(q1, hand.lower, hand.upper)))
    return out
