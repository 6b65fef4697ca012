"""The swept check of a hand command's segment (teleprev.pipeline.swept.SweptCheck), in compiled code:
the link-motion bound, the points along the segment, each point's self-collision test with the grown
and the plain shapes, the end point's clearance, and the bisection for the last free point.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from teleprev.kernels.collision import Margins, self_collision_margins_into
from teleprev.kernels.fk import FkTable, fk_into


class SweptTable(NamedTuple):
    reach: np.ndarray  # (links, joints): R[L, j] bounds how far a point of link L moves per radian of joint j
    spacing: float  # half the clearance (0: none): the largest link motion between two checked points
    start_step: float  # the same from a start inside the margin (plain shapes)


class SweptShapes(NamedTuple):
    """A BoxTable for two shape sets of one robot: the shapes grown by half the clearance (row 0 of
    shape_local, shape_size and spheres) and the plain ones (row 1); the same links, boxes and pairs."""

    shape_link: np.ndarray  # (S,) int64
    shape_local: np.ndarray  # (2, S, 3, 4)
    shape_size: np.ndarray  # (2, S, 4)
    links: np.ndarray  # (m, 3) int64
    spheres: np.ndarray  # (2, m, 4)
    pairs: np.ndarray  # (P, 2) int64

# A configuration's state under one checker: FREE / COLLIDING where the compiled test is decisive, UNSURE
# where its answer is within the margin (the loose test finds a contact, the tight one none): FCL decides.
POINT_FREE, POINT_COLLIDING, POINT_UNSURE = 0, 1, 2
# swept_segment's answers. COLLIDES / FREE decide the segment. UNSURE_*: FCL must decide the configuration
# left in `point` (START: q0 with the grown shapes, GROWN: point k with them, PLAIN: point k with the plain
# shapes, END: the end point with the grown shapes), then the caller goes on. BAD: inputs the kernel
# does not take (not finite, or too many points): the caller runs the numpy check.
SWEPT_COLLIDES, SWEPT_FREE, SWEPT_UNSURE_START, SWEPT_UNSURE_GROWN, SWEPT_UNSURE_PLAIN, SWEPT_UNSURE_END, SWEPT_BAD = (
    0, 1, 2, 3, 4, 5, 6)
SWEPT_MAX_POINTS = 1e7


@njit(cache=True)
def _swept_point(q, which, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres,
                 pairs, loose, tight, world, hits, labels, index):
    """POINT_* of configuration q under shape set `which` (0 grown, 1 plain): the loose test (margin
    `loose`) clears it, or the tight one (margin `tight`) confirms a contact, or neither (UNSURE); both
    margins in one pass (self_collision_margins_into)."""
    fk_into(q, link_int, link_num, link_terms, world)
    state = self_collision_margins_into(world, shape_link, shape_local[which], shape_size[which], links,
                                        spheres[which], pairs, loose, tight, True, hits, labels, index)
    if state == 0:
        return POINT_FREE
    return POINT_COLLIDING if state > 0 else POINT_UNSURE


@njit(cache=True)
def _swept(q0, q1, q0_clear, start, reach, spacing, start_step, link_int, link_num, link_terms, shape_link,
           shape_local, shape_size, links, spheres, pairs, loose, tight, world, hits, labels, index, point):
    """SweptCheck.segment_free from point `start` on: (answer, k, q0_clear, end_clear).

    q0_clear: whether q0 keeps the clearance (1 / 0), -1 if not known yet (then it is checked here and
    returned). end_clear: the end point's clearance when it was checked (1 / 0), else -1. k: the point
    an UNSURE answer is about (1..n), -1 when q0 == q1. shape_local / shape_size / spheres stack the
    grown shapes (row 0) on the plain ones (row 1); spacing: half the clearance (0: none).
    """
    n_q = q0.shape[0]
    same = True
    for i in range(n_q):
        if not (np.isfinite(q0[i]) and np.isfinite(q1[i])):
            return SWEPT_BAD, 0, q0_clear, -1
        if q0[i] != q1[i]:
            same = False
    if same:
        return SWEPT_FREE, -1, q0_clear, -1
    # the link-motion bound: max over links of sum_j R[L, j] |dq_j|
    bound = 0.0
    for row in range(reach.shape[0]):
        s = 0.0
        for j in range(n_q):
            s += reach[row, j] * abs(q1[j] - q0[j])
        if s > bound:
            bound = s
    grown = False
    if spacing > 0:
        if q0_clear < 0:
            state = _swept_point(q0, 0, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links,
                                 spheres, pairs, loose, tight, world, hits, labels, index)
            if state == POINT_UNSURE:
                point[:] = q0
                return SWEPT_UNSURE_START, 0, q0_clear, -1
            q0_clear = 1 if state == POINT_FREE else 0
        grown = q0_clear == 1
    x = bound / (spacing if grown else start_step)
    if not x <= SWEPT_MAX_POINTS:
        return SWEPT_BAD, 0, q0_clear, -1
    n = max(1, int(np.ceil(x)))
    which = 0 if grown else 1
    for k in range(start, n + 1):
        f = k / n
        for i in range(n_q):
            point[i] = q0[i] + f * (q1[i] - q0[i])  # numpy's q0 + (k / n) * (q1 - q0), element by element
        state = _swept_point(point, which, link_int, link_num, link_terms, shape_link, shape_local, shape_size,
                             links, spheres, pairs, loose, tight, world, hits, labels, index)
        if grown and k == n:  # the end point keeps the full clearance
            if state == POINT_UNSURE:
                return SWEPT_UNSURE_END, k, q0_clear, -1
            return (SWEPT_FREE if state == POINT_FREE else SWEPT_COLLIDES), k, q0_clear, 1 if state == POINT_FREE else 0
        if state == POINT_COLLIDING:
            return SWEPT_COLLIDES, k, q0_clear, -1
        if state == POINT_UNSURE:
            return (SWEPT_UNSURE_GROWN if grown else SWEPT_UNSURE_PLAIN), k, q0_clear, -1
    return SWEPT_FREE, n, q0_clear, -1


@njit(cache=True)
def swept_segment(q0, q1, q0_clear, start, reach, spacing, start_step, link_int, link_num, link_terms, shape_link,
                  shape_local, shape_size, links, spheres, pairs, loose, tight, point):
    """One segment's swept check (see _swept): (answer, k, q0_clear, end_clear)."""
    world = np.empty((link_int.shape[0], 4, 4))
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    return _swept(q0, q1, q0_clear, start, reach, spacing, start_step, link_int, link_num, link_terms, shape_link,
                  shape_local, shape_size, links, spheres, pairs, loose, tight, world, hits, labels, index, point)


@njit(cache=True)
def swept_last_free(q0, q1, steps, q0_clear, reach, spacing, start_step, link_int, link_num, link_terms, shape_link,
                    shape_local, shape_size, links, spheres, pairs, loose, tight, point, cached):
    """SweptCheck.last_free_on_segment's bisection: (answer, lo, q0_clear, cache).

    answer SWEPT_FREE: lo is the bisection's result. Any other answer (a configuration within the margin,
    or inputs the kernel does not take): the caller runs the bisection itself. cache: the last clearance
    check, as SweptCheck.clear's cache would hold it: 0 none, 1 q0 (its clearance q0_clear), 2 + its
    clearance (0 / 1) for the end point of a segment, left in `cached`.
    """
    world = np.empty((link_int.shape[0], 4, 4))
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    qm = np.empty_like(q0)
    lo = 0.0
    hi = 1.0
    cache = 0
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        for i in range(q0.shape[0]):
            qm[i] = q0[i] + mid * (q1[i] - q0[i])
        answer, k, q0_clear, end_clear = _swept(q0, qm, q0_clear, 1, reach, spacing, start_step, link_int, link_num,
                                                link_terms, shape_link, shape_local, shape_size, links, spheres,
                                                pairs, loose, tight, world, hits, labels, index, point)
        if answer > SWEPT_FREE:
            return answer, lo, q0_clear, cache
        if end_clear >= 0:
            cached[:] = point
            cache = 2 + end_clear
        elif k >= 0 and spacing > 0:
            cache = 1
        if answer == SWEPT_FREE:
            lo = mid
        else:
            hi = mid
    return SWEPT_FREE, lo, q0_clear, cache


@njit(cache=True, inline="always")
def _np_max(a, b):
    """np.maximum of two floats: NaN if either is, else the larger (the second on a tie)."""
    if a != a or b != b:
        return a + b
    return a if a > b else b


@njit(cache=True, inline="always")
def _np_min(a, b):
    if a != a or b != b:
        return a + b
    return a if a < b else b


@njit(cache=True)
def swept_command(q0, q1, v1, acceleration, lower, upper, q0_clear, q1_clear, reach, spacing, start_step, link_int,
                  link_num, link_terms, shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight,
                  point):
    """A hand command's two checks in one call: the segment q0 -> q1, then q1 -> where braking at
    `acceleration` from q1 at v1 ends within [lower, upper] (Motion._stop_point's arithmetic).

    Returns (answer, cache, clear, q1_clear). answer SWEPT_FREE / SWEPT_COLLIDES: decided without FCL; any
    other: the caller runs the two checks one by one. q0_clear / q1_clear: their clearance as the caller's
    cache knows it (-1: not known). cache, clear: the last clearance check, as SweptCheck.clear's cache would
    hold it after the two checks: 0 none, 1 q0, 2 q1, 3 the end point left in `point`; clear its answer.
    q1_clear on the way out: q1's clearance where it is known now (the first segment's end point is q1 bit
    for bit), else -1; the next command's segment starts at q1.
    """
    world = np.empty((link_int.shape[0], 4, 4))
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    n_q = q1.shape[0]
    stop = np.empty(n_q)
    for i in range(n_q):
        v = v1[i]
        stop[i] = _np_min(_np_max(q1[i] + v * abs(v) / (2.0 * acceleration[i]), lower[i]), upper[i])
    cache = 0
    clear = 0
    answer, k, c0, end = _swept(q0, q1, q0_clear, 1, reach, spacing, start_step, link_int, link_num, link_terms,
                                shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world,
                                hits, labels, index, point)
    if answer > SWEPT_FREE:
        return answer, 0, 0, -1
    if end >= 0:
        cache, clear = 3, end
        same = True  # the cache holds the end point, which is q1 only if equal bit for bit
        for i in range(n_q):
            if point[i] != q1[i] or np.copysign(1.0, point[i]) != np.copysign(1.0, q1[i]):
                same = False
        q1_clear = end if same else -1
    elif k >= 0 and spacing > 0:
        cache, clear = 1, c0
        q1_clear = -1  # the cache holds q0, which differs from q1
    if answer == SWEPT_COLLIDES:
        return answer, cache, clear, q1_clear
    answer, k, c1, end = _swept(q1, stop, q1_clear, 1, reach, spacing, start_step, link_int, link_num, link_terms,
                                shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world,
                                hits, labels, index, point)
    if answer > SWEPT_FREE:
        return answer, 0, 0, -1
    if end >= 0:
        cache, clear = 3, end
    elif k >= 0 and spacing > 0:
        cache, clear = 2, c1
    return answer, cache, clear, c1 if spacing > 0 else -1


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "swept_segment": ("q0", "q1", "q0_clear", "start", SweptTable, FkTable, SweptShapes, Margins, "point"),
    "swept_last_free": ("q0", "q1", "steps", "q0_clear", SweptTable, FkTable, SweptShapes, Margins, "point",
                        "cached"),
    "swept_command": ("q0", "q1", "v1", "acceleration", "lower", "upper", "q0_clear", "q1_clear", SweptTable,
                      FkTable, SweptShapes, Margins, "point"),
}
