"""The swept check of a hand command's segment (teleprev.pipeline.swept.SweptCheck), in compiled code:
the link-motion bound, the points along the segment, each point's self-collision test with the grown
and the plain shapes, the end point's clearance, the bisection for the last free point, and the search
for a command that holds back only the fingers whose motion would collide (swept_slide).
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
class Fingers(NamedTuple):
    """The hand's kinematic chains from the palm (one per finger): which one each joint moves and each
    checked link belongs to."""

    joint_finger: np.ndarray  # (n,) int64: the finger a joint moves (-1: none)
    link_finger: np.ndarray  # (m,) int64: the finger of each checked link (-1: the palm, which no joint moves)
    fingers: int


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


@njit(cache=True)
def _loose_pair(q, which, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres, pairs,
                loose, world, hits, labels, index):
    """A checked pair that the loose test (shape set `which`) finds in contact at q, -1 if none."""
    fk_into(q, link_int, link_num, link_terms, world)
    state = self_collision_margins_into(world, shape_link, shape_local[which], shape_size[which], links,
                                        spheres[which], pairs, loose, loose, True, hits, labels, index)
    return index[0] if state > 0 else -1


@njit(cache=True)
def _command_pair(q0, q0_clear, q1, v1, acceleration, lower, upper, reach, spacing, start_step, link_int, link_num,
                  link_terms, shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world, hits,
                  labels, index, point, stop):
    """swept_command's two checks of a command q1 from q0, for the slide: (answer, q0_clear, pair, points),
    points: about how many configurations the checks tested (the slide's budget counts them).

    answer SWEPT_FREE: both segments keep the clearance, decided without FCL. SWEPT_COLLIDES: not shown
    free; pair is a checked pair in contact (for the loose test where the compiled test is within its
    margin, which counts as not free here) at the first configuration found, -1 if none is known.
    SWEPT_BAD: q0's own clearance is within the margin, or inputs the kernel does not take."""
    for i in range(q1.shape[0]):
        v = v1[i]
        stop[i] = _np_min(_np_max(q1[i] + v * abs(v) / (2.0 * acceleration[i]), lower[i]), upper[i])
    answer, k, q0_clear, end = _swept(q0, q1, q0_clear, 1, reach, spacing, start_step, link_int, link_num, link_terms,
                                      shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world,
                                      hits, labels, index, point)
    points = 1 + max(k, 0)
    if answer == SWEPT_UNSURE_START or answer == SWEPT_BAD:
        return SWEPT_BAD, q0_clear, -1, points
    grown = spacing > 0 and q0_clear == 1
    if answer == SWEPT_FREE:
        answer, k, c1, end = _swept(q1, stop, -1, 1, reach, spacing, start_step, link_int, link_num, link_terms,
                                    shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world,
                                    hits, labels, index, point)
        points += 1 + max(k, 0)
        if answer == SWEPT_FREE:
            return SWEPT_FREE, q0_clear, -1, points
        if answer == SWEPT_BAD:
            return SWEPT_BAD, q0_clear, -1, points
        grown = spacing > 0 and (c1 == 1 or answer == SWEPT_UNSURE_START)  # (START: q1 itself, in point)
    if answer == SWEPT_COLLIDES:
        return SWEPT_COLLIDES, q0_clear, index[0], points
    which = 1 if answer == SWEPT_UNSURE_PLAIN or not grown else 0
    return SWEPT_COLLIDES, q0_clear, _loose_pair(point, which, link_int, link_num, link_terms, shape_link, shape_local,
                                                 shape_size, links, spheres, pairs, loose, world, hits, labels,
                                                 index), points + 1


@njit(cache=True)
def _place(q0, base, stop, track, fraction, joints, dt, out):
    """A candidate command in out[0], its velocity from q0 in out[1]: on `joints` (a mask) the fraction of
    the way from stop to track (1: track itself, bit for bit; else held between the two, so that rounding
    cannot take it past either), base elsewhere."""
    for i in range(q0.shape[0]):
        if not joints[i]:
            c = base[i]
        elif fraction == 1.0:
            c = track[i]
        else:
            c = stop[i] + fraction * (track[i] - stop[i])
            c = _np_min(_np_max(c, min(stop[i], track[i])), max(stop[i], track[i]))
        out[0, i] = c
        out[1, i] = (c - q0[i]) / dt


@njit(cache=True)
def swept_slide(q0, q0_clear, track, stop, away, target, dt, acceleration, lower, upper, steps, budget,
                joint_finger, link_finger, fingers, reach, spacing, start_step, link_int, link_num, link_terms,
                shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, point, out):
    """A hand command from q0 that holds back only the fingers whose motion would collide: (answer, held,
    q0_clear); where answer is SWEPT_FREE, the command and its velocity are in out[0], out[1].

    Each joint's command lies between `stop` (braking, one step) and `track` (the capped step towards
    the target), which both keep the limits, so any point between them keeps them too. Every candidate
    is checked as swept_command checks a command (its segment, and the way on to where braking from it
    would stop), and only one shown free without FCL is taken: a configuration within the compiled
    test's margin counts as not free here.
    1. Which fingers brake: at first none; while the candidate is not free, of the colliding pair's
       fingers that still track, the one whose link moves more (by the reach bound) brakes.
    2. Each braked finger, in that order, slides: its joints one by one, the most moving first, each
       taking its whole step where the command stays free, then the joints that could not, together,
       as far along their step as a bisection of `steps` halvings finds free.
    3. A braked finger that got nowhere (still at its braking step) and the finger of the pair that
       braked it may each be in the other's way (two interleaved fingers, which 1-2 hold for good):
       the one nearer its `target` gives way, its joints stepping away from their targets (to `away`:
       the limiter's capped step towards the lower limit, row 0, or the upper, row 1), while the other
       takes its whole step, else while it stays.
    At most fingers + 1 + (joints + steps) per braked finger checks in 1-2 (a LEAP Hand: at most 41, one
    blocked finger: about 11), at most 2 (2 joints + 1) per stuck finger in 3 (LEAP: 18), and no new check
    once `budget` configurations have been tested (a count, so a re-run finds the same command): then the
    search keeps what it found free so far, and where that is nothing yet, answers SWEPT_COLLIDES.
    held: bit f set for a finger left short of its step. SWEPT_COLLIDES: no finger-wise command (the
    colliding pair's fingers brake already, or no pair is known): the caller brakes the whole hand.
    SWEPT_BAD: q0 within the margin, or inputs the kernel does not take: the same."""
    n = q0.shape[0]
    world = np.empty((link_int.shape[0], 4, 4))
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    stop_point = np.empty(n)
    joints = np.empty(n, dtype=np.bool_)
    braked = np.zeros(max(fingers, 1), dtype=np.bool_)
    order = np.empty(max(fingers, 1), dtype=np.int64)
    partner = np.full(max(fingers, 1), -1, dtype=np.int64)  # the other finger of the pair that braked it
    count = 0
    used = 0
    while True:
        if used >= budget:
            return SWEPT_COLLIDES, 0, q0_clear
        for i in range(n):
            joints[i] = joint_finger[i] < 0 or not braked[joint_finger[i]]
        _place(q0, stop, stop, track, 1.0, joints, dt, out)
        answer, q0_clear, pair, points = _command_pair(q0, q0_clear, out[0], out[1], acceleration, lower, upper, reach,
                                                       spacing, start_step, link_int, link_num, link_terms, shape_link,
                                                       shape_local, shape_size, links, spheres, pairs, loose, tight,
                                                       world, hits, labels, index, point, stop_point)
        used += points
        if answer != SWEPT_COLLIDES:
            break
        choice, most = -1, 0.0
        for side in range(2 if pair >= 0 else 0):
            link = pairs[pair, side]
            f = link_finger[link]
            if f < 0 or braked[f]:
                continue
            moved = 0.0
            for j in range(n):
                if joint_finger[j] == f:
                    moved += reach[link, j] * abs(track[j] - stop[j])
            if moved > most:
                choice, most = f, moved
        if choice < 0:
            return SWEPT_COLLIDES, 0, q0_clear
        other = link_finger[pairs[pair, 0]]
        partner[choice] = link_finger[pairs[pair, 1]] if other == choice else other
        braked[choice] = True
        order[count] = choice
        count += 1
    if answer == SWEPT_BAD:
        return SWEPT_BAD, 0, q0_clear
    best = out.copy()
    held = 0
    taken = np.empty(n, dtype=np.bool_)
    for b in range(count):
        f = order[b]
        # its joints, one by one, the most moving first: each takes its whole step where that is free
        taken[:] = False
        rest = False
        while True:
            pick, most = -1, 0.0
            for j in range(n):
                if joint_finger[j] == f and not taken[j] and abs(track[j] - stop[j]) > most:
                    pick, most = j, abs(track[j] - stop[j])
            if pick < 0:
                break
            if used >= budget:
                rest = True
                break
            taken[pick] = True
            joints[:] = False
            joints[pick] = True
            _place(q0, best[0], stop, track, 1.0, joints, dt, out)
            answer, q0_clear, pair, points = _command_pair(q0, q0_clear, out[0], out[1], acceleration, lower, upper,
                                                           reach, spacing, start_step, link_int, link_num, link_terms,
                                                           shape_link, shape_local, shape_size, links, spheres, pairs,
                                                           loose, tight, world, hits, labels, index, point, stop_point)
            used += points
            if answer == SWEPT_BAD:
                return SWEPT_BAD, 0, q0_clear
            if answer == SWEPT_FREE:
                best[:] = out
            else:
                rest = True
        if not rest:
            continue  # the finger takes its whole step
        held |= 1 << f
        # the joints that could not: together, as far along their step as is free
        for j in range(n):
            joints[j] = joint_finger[j] == f and best[0, j] != track[j]
        base = best[0].copy()
        lo, hi = 0.0, 1.0
        for _ in range(steps):
            if used >= budget:
                break
            mid = 0.5 * (lo + hi)
            _place(q0, base, stop, track, mid, joints, dt, out)
            answer, q0_clear, pair, points = _command_pair(q0, q0_clear, out[0], out[1], acceleration, lower, upper,
                                                           reach, spacing, start_step, link_int, link_num, link_terms,
                                                           shape_link, shape_local, shape_size, links, spheres, pairs,
                                                           loose, tight, world, hits, labels, index, point, stop_point)
            used += points
            if answer == SWEPT_BAD:
                return SWEPT_BAD, 0, q0_clear
            if answer == SWEPT_FREE:
                lo = mid
                best[:] = out
            else:
                hi = mid
    # 3. A held finger that did not move past its braking step and the finger of the pair that braked it
    #    (its partner) may be in each other's way (two interleaved fingers): the one nearer its target
    #    gives way, so that the other takes its whole step. The giver's joints retreat one at a time (the
    #    model's order: the abduction first), then together: each to its capped step away from its
    #    target (`away`: row 0 the step towards the lower limit, row 1 the upper; a joint at its target
    #    tries both). The first free candidate is taken.
    for b in range(count):
        f = order[b]
        g = partner[f]
        if g < 0 or g == f or not held >> f & 1 or used >= budget:
            continue
        stuck = True
        for j in range(n):
            if joint_finger[j] == f and best[0, j] != stop[j]:
                stuck = False
        if not stuck:
            continue
        far_f = far_g = 0.0
        for j in range(n):
            if joint_finger[j] == f:
                far_f = max(far_f, abs(target[j] - q0[j]))
            elif joint_finger[j] == g:
                far_g = max(far_g, abs(target[j] - q0[j]))
        mover, giver = (f, g) if far_f >= far_g else (g, f)
        for j in range(n):
            joints[j] = joint_finger[j] == mover
        _place(q0, best[0], stop, track, 1.0, joints, dt, out)
        stepped = out[0].copy()
        found = False
        for c in range(4 * n + 2):  # with the mover's whole step, then with the mover held
            with_step = c < 2 * n + 1
            base = stepped if with_step else best[0]
            c = c % (2 * n + 1)
            j0 = c >> 1
            if c < 2 * n:
                if joint_finger[j0] != giver:
                    continue
                side = c & 1
                if target[j0] != q0[j0] and side != (1 if target[j0] < q0[j0] else 0):
                    continue
            if used >= budget:
                break
            for j in range(n):
                out[0, j] = base[j]
                if joint_finger[j] == giver and (c == 2 * n or j == j0):
                    side = (c & 1) if c < 2 * n else (1 if target[j] < q0[j] else 0)
                    if c == 2 * n and target[j] == q0[j]:
                        continue
                    out[0, j] = away[side, j]
                out[1, j] = (out[0, j] - q0[j]) / dt
            answer, q0_clear, pair, points = _command_pair(q0, q0_clear, out[0], out[1], acceleration, lower, upper,
                                                           reach, spacing, start_step, link_int, link_num, link_terms,
                                                           shape_link, shape_local, shape_size, links, spheres, pairs,
                                                           loose, tight, world, hits, labels, index, point, stop_point)
            used += points
            if answer == SWEPT_BAD:
                return SWEPT_BAD, 0, q0_clear
            if answer == SWEPT_FREE:
                if with_step:
                    held = (held & ~(1 << mover)) | (1 << giver)
                best[:] = out
                found = True
                break
        if found:
            break
    out[:] = best
    return SWEPT_FREE, held, q0_clear


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "swept_segment": ("q0", "q1", "q0_clear", "start", SweptTable, FkTable, SweptShapes, Margins, "point"),
    "swept_last_free": ("q0", "q1", "steps", "q0_clear", SweptTable, FkTable, SweptShapes, Margins, "point",
                        "cached"),
    "swept_command": ("q0", "q1", "v1", "acceleration", "lower", "upper", "q0_clear", "q1_clear", SweptTable,
                      FkTable, SweptShapes, Margins, "point"),
    "swept_slide": ("q0", "q0_clear", "track", "stop", "away", "target", "dt", "acceleration", "lower", "upper",
                    "steps", "budget", Fingers,
                    SweptTable, FkTable, SweptShapes, Margins, "point", "out"),
}
