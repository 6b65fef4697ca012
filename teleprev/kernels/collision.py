"""Self-collision of a robot whose collision geometry is boxes: FK, box poses and bounding spheres
once per configuration, then every checked link pair culled by spheres and decided by the box test
(teleprev.kernels.boxes), for two margins at once (teleprev.robot.collision.SelfCollisionChecker).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from teleprev.kernels.boxes import BOX_APART, BOX_BOTH, _place, boxes_state
from teleprev.kernels.fk import FkTable, fk, fk_into


class BoxTable(NamedTuple):
    """A robot's collision boxes (S of them, grouped by checked link) and its checked link pairs."""

    shape_link: np.ndarray  # (S,) int64: the model link (FK row) of each box
    shape_local: np.ndarray  # (S, 3, 4) the box's pose in that link
    shape_size: np.ndarray  # (S, 4) half extents, then the bounding sphere's radius
    links: np.ndarray  # (m, 3) int64: per checked link, its model link and the range [start, stop) of its boxes
    spheres: np.ndarray  # (m, 4) per checked link, a bounding sphere of its boxes (centre in the link, radius)
    pairs: np.ndarray  # (P, 2) int64: the checked link pairs


class Margins(NamedTuple):
    """The two margins one pass decides (loose >= tight; equal: the one-margin test)."""

    loose: float
    tight: float

@njit(cache=True, inline="always")
def _apart2(x, y, reach):
    """Whether two points (3-vectors) are further apart than reach (reach >= 0)."""
    dx = x[0] - y[0]
    dy = x[1] - y[1]
    dz = x[2] - y[2]
    return dx * dx + dy * dy + dz * dz > reach * reach


# ---- self-collision, both margins in one pass (SelfCollisionChecker) ----------------------------
# SelfCollisionChecker's compiled decision: the test with the margin `loose` (MARGIN: FCL's contacts and
# more) and with `tight` (-MARGIN: fewer), FK, box poses and bounding spheres computed once. Every cull
# and every axis is compared with both margins in the same expressions, so the answers are those of two
# one-margin calls (tests/robot/test_compiled_collision.py).
MARGINS_UNSURE = -1  # the two margins disagree on some pair (within the margin of touching): FCL decides


@njit(cache=True)
def self_collision_margins_into(world, shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight,
                                first_only, hits, labels, index):
    """Colliding checked-link pairs under the margins `loose` and `tight` (loose >= tight) at once.

    world (L, 4, 4): link transforms. Boxes (S of them, grouped by checked link): shape_link (S,) the
    model link, shape_local (S, 3, 4) the pose in that link, shape_size (S, 4) half extents and
    bounding-sphere radius. Checked links: links (m, 3) the model link and the range [start, stop) of
    its boxes, spheres (m, 4) a bounding sphere of those boxes (centre in the link frame, radius).
    pairs (P, 2): the checked link pairs. With loose == tight it is the one-margin test
    (CompiledSelfCollisionChecker): MARGINS_UNSURE never arises.
    Without first_only: the number n of pairs colliding for both margins, when no pair collides for the
    loose one alone (the two calls' answers are equal): hits (P,) and labels (m,) set, index[:n] the
    pairs in order. MARGINS_UNSURE as soon as a pair collides for the loose margin only (hits, labels and
    index then partial). With first_only: 1 at the first pair colliding for both margins, 0 when none
    collides for the loose margin, MARGINS_UNSURE when some do but none for the tight one.
    Bounding spheres cull first: link against link, box against the other link, box against box; a
    sphere apart by more than `tight` but not `loose` leaves only the loose question for the boxes inside.
    """
    n_shapes = shape_link.shape[0]
    boxes = np.empty((n_shapes, 3, 4))
    for k in range(n_shapes):
        _place(world, shape_link[k], shape_local[k], boxes, k)
    n_links = links.shape[0]
    centres = np.empty((n_links, 3))
    for k in range(n_links):
        w = links[k, 0]
        for r in range(3):
            centres[k, r] = (world[w, r, 0] * spheres[k, 0] + world[w, r, 1] * spheres[k, 1]
                             + world[w, r, 2] * spheres[k, 2] + world[w, r, 3])
    count = 0
    loose_only = False
    for p in range(pairs.shape[0]):
        la = pairs[p, 0]
        lb = pairs[p, 1]
        reach = spheres[la, 3] + spheres[lb, 3]
        if _apart2(centres[la], centres[lb], reach + loose):
            continue
        tight_l = not _apart2(centres[la], centres[lb], reach + tight)
        loose_hit = False
        tight_hit = False
        for a in range(links[la, 1], links[la, 2]):
            reach = shape_size[a, 3] + spheres[lb, 3]
            if _apart2(boxes[a, :, 3], centres[lb], reach + loose):
                continue
            tight_a = tight_l and not _apart2(boxes[a, :, 3], centres[lb], reach + tight)
            for b in range(links[lb, 1], links[lb, 2]):
                reach = shape_size[a, 3] + shape_size[b, 3]
                if _apart2(boxes[a, :, 3], boxes[b, :, 3], reach + loose):
                    continue
                tight_b = tight_a and not _apart2(boxes[a, :, 3], boxes[b, :, 3], reach + tight)
                state = boxes_state(boxes, a, b, shape_size, loose, tight)
                if state == BOX_APART:
                    continue
                loose_hit = True
                if tight_b and state == BOX_BOTH:
                    tight_hit = True
                    break
            if tight_hit:
                break
        if tight_hit:
            hits[p] = True
            labels[la] = True
            labels[lb] = True
            index[count] = p
            count += 1
            if first_only:
                return count
        elif loose_hit:
            if not first_only:
                return MARGINS_UNSURE
            loose_only = True
    return MARGINS_UNSURE if loose_only else count


@njit(cache=True)
def check_margins(q, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres, pairs,
                  loose, tight, first_only, labels, index):
    """FK, then self_collision_margins_into for one configuration: its answer (labels (m,) zeros on the
    way in, index (P,) scratch)."""
    world = fk(q, link_int, link_num, link_terms)
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    return self_collision_margins_into(world, shape_link, shape_local, shape_size, links, spheres, pairs, loose,
                                       tight, first_only, hits, labels, index)


@njit(cache=True)
def collides_margins(q, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links, spheres, pairs,
                     loose, tight):
    """check_margins with first_only, its scratch arrays its own: 1, 0 or MARGINS_UNSURE."""
    world = fk(q, link_int, link_num, link_terms)
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(1, dtype=np.int64)
    return self_collision_margins_into(world, shape_link, shape_local, shape_size, links, spheres, pairs, loose,
                                       tight, True, hits, labels, index)


@njit(cache=True)
def pair_matrix_margins_world(world, shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight):
    """(N, P) pairs colliding for both margins, and (N,) whether a row is unsure (some pair collides for
    the loose margin only; its row is then partial), of a batch given its link transforms (N, L, 4, 4)."""
    n = world.shape[0]
    hits = np.zeros((n, pairs.shape[0]), dtype=np.bool_)
    unsure = np.zeros(n, dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    for k in range(n):
        unsure[k] = self_collision_margins_into(world[k], shape_link, shape_local, shape_size, links, spheres, pairs,
                                                loose, tight, False, hits[k], labels, index) < 0
    return hits, unsure


@njit(cache=True)
def first_colliding_margins(qs, start, link_int, link_num, link_terms, shape_link, shape_local, shape_size, links,
                            spheres, pairs, loose, tight):
    """The first configuration of qs (N, n) from `start` on that collides for the loose margin: (k, 1)
    if it collides for the tight one too, (k, MARGINS_UNSURE) if not; (-1, 0) if none does."""
    world = np.empty((link_int.shape[0], 4, 4))
    hits = np.zeros(pairs.shape[0], dtype=np.bool_)
    labels = np.zeros(links.shape[0], dtype=np.bool_)
    index = np.empty(pairs.shape[0], dtype=np.int64)
    for k in range(start, qs.shape[0]):
        fk_into(qs[k], link_int, link_num, link_terms, world)
        state = self_collision_margins_into(world, shape_link, shape_local, shape_size, links, spheres, pairs, loose,
                                            tight, True, hits, labels, index)
        if state != 0:
            return k, state
    return -1, 0


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "self_collision_margins_into": ("world", BoxTable, Margins, "first_only", "hits", "labels", "index"),
    "check_margins": ("q", FkTable, BoxTable, Margins, "first_only", "labels", "index"),
    "collides_margins": ("q", FkTable, BoxTable, Margins),
    "pair_matrix_margins_world": ("world", BoxTable, Margins),
    "first_colliding_margins": ("qs", "start", FkTable, BoxTable, Margins),
}
