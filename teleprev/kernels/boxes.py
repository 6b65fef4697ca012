"""The exact test of two oriented boxes (the separating-axis theorem, 15 candidate axes), deciding two
margins in one pass.

A pair counts as apart only when some axis separates it by more than `margin`; `MARGIN` (1 nm) makes
every rounding difference against another implementation (FCL) fall on the "colliding" side. Cross
products of nearly parallel edges are close to zero vectors, where rounding alone could make 0 > 0 true;
padding |R| by `_PAD` keeps such an axis from ever separating a pair that the face axes do not (it can
only err towards "colliding").
"""

from __future__ import annotations

import numpy as np
from numba import njit

MARGIN = 1e-9  # metres: boxes closer than this along every axis count as touching
_PAD = 1e-12  # added to |R| for the edge-edge axes (see the module docstring)


@njit(cache=True, inline="always")
def _place(world, link, local, out, k):
    """out[k] (3, 4) = world[link] @ local (3, 4): a rigid transform's top rows."""
    for r in range(3):
        w0, w1, w2 = world[link, r, 0], world[link, r, 1], world[link, r, 2]
        out[k, r, 0] = w0 * local[0, 0] + w1 * local[1, 0] + w2 * local[2, 0]
        out[k, r, 1] = w0 * local[0, 1] + w1 * local[1, 1] + w2 * local[2, 1]
        out[k, r, 2] = w0 * local[0, 2] + w1 * local[1, 2] + w2 * local[2, 2]
        out[k, r, 3] = w0 * local[0, 3] + w1 * local[1, 3] + w2 * local[2, 3] + world[link, r, 3]


# The separating-axis test decides two margins in one pass (SelfCollisionChecker's decision): a pair's
# state under the loose margin (FCL's contacts and more) and the tight one (fewer) from the same
# arithmetic; loose >= tight, so an axis that separates by more than `loose` separates by more than
# `tight` too and decides both. With loose == tight it is the one-margin test (boxes_apart).
BOX_APART, BOX_LOOSE, BOX_BOTH = 0, 1, 2  # apart for both margins / colliding for the loose one only / for both


@njit(cache=True, inline="always")
def _edge_state(tx, rx, ty, ry, reach, loose, tight, tight_apart):
    """One edge-edge axis: -1 if it separates by more than `loose`, else whether it (or an earlier axis:
    tight_apart) separates by more than `tight` (1 / 0). The unnormalised axis has length |(rx, ry)|, so
    the margins scale with it."""
    gap = abs(tx * rx - ty * ry) - reach
    length = np.sqrt(rx * rx + ry * ry)
    if gap > loose * length:
        return -1
    return 1 if tight_apart or gap > tight * length else 0


@njit(cache=True, inline="always")
def boxes_state(boxes, a, b, size, loose, tight):
    """BOX_APART if one of the 15 SAT axes separates boxes a and b by more than `loose`; else BOX_LOOSE if
    one separates them by more than `tight`; else BOX_BOTH (loose >= tight).

    boxes (S, 3, 4): poses (columns 0-2 the box axes in the world, column 3 the centre); size (S, 4):
    half extents first. In box a's frame: rij = a_i . b_j, t = offset of b's centre; pij = |rij| + _PAD.
    Written out in scalars: with loops and scratch arrays the test costs several times more.
    """
    ha0, ha1, ha2 = size[a, 0], size[a, 1], size[a, 2]
    hb0, hb1, hb2 = size[b, 0], size[b, 1], size[b, 2]
    d0 = boxes[b, 0, 3] - boxes[a, 0, 3]
    d1 = boxes[b, 1, 3] - boxes[a, 1, 3]
    d2 = boxes[b, 2, 3] - boxes[a, 2, 3]
    a00, a10, a20 = boxes[a, 0, 0], boxes[a, 1, 0], boxes[a, 2, 0]
    a01, a11, a21 = boxes[a, 0, 1], boxes[a, 1, 1], boxes[a, 2, 1]
    a02, a12, a22 = boxes[a, 0, 2], boxes[a, 1, 2], boxes[a, 2, 2]
    b00, b10, b20 = boxes[b, 0, 0], boxes[b, 1, 0], boxes[b, 2, 0]
    b01, b11, b21 = boxes[b, 0, 1], boxes[b, 1, 1], boxes[b, 2, 1]
    b02, b12, b22 = boxes[b, 0, 2], boxes[b, 1, 2], boxes[b, 2, 2]

    # a's face normals, one row of R at a time so that an early exit skips the rest
    t0 = a00 * d0 + a10 * d1 + a20 * d2
    r00 = a00 * b00 + a10 * b10 + a20 * b20
    r01 = a00 * b01 + a10 * b11 + a20 * b21
    r02 = a00 * b02 + a10 * b12 + a20 * b22
    q00, q01, q02 = abs(r00), abs(r01), abs(r02)
    gap = abs(t0) - (ha0 + hb0 * q00 + hb1 * q01 + hb2 * q02)
    if gap > loose:
        return BOX_APART
    tight_apart = gap > tight
    t1 = a01 * d0 + a11 * d1 + a21 * d2
    r10 = a01 * b00 + a11 * b10 + a21 * b20
    r11 = a01 * b01 + a11 * b11 + a21 * b21
    r12 = a01 * b02 + a11 * b12 + a21 * b22
    q10, q11, q12 = abs(r10), abs(r11), abs(r12)
    gap = abs(t1) - (ha1 + hb0 * q10 + hb1 * q11 + hb2 * q12)
    if gap > loose:
        return BOX_APART
    tight_apart = tight_apart or gap > tight
    t2 = a02 * d0 + a12 * d1 + a22 * d2
    r20 = a02 * b00 + a12 * b10 + a22 * b20
    r21 = a02 * b01 + a12 * b11 + a22 * b21
    r22 = a02 * b02 + a12 * b12 + a22 * b22
    q20, q21, q22 = abs(r20), abs(r21), abs(r22)
    gap = abs(t2) - (ha2 + hb0 * q20 + hb1 * q21 + hb2 * q22)
    if gap > loose:
        return BOX_APART
    tight_apart = tight_apart or gap > tight

    # b's face normals
    gap = abs(t0 * r00 + t1 * r10 + t2 * r20) - (ha0 * q00 + ha1 * q10 + ha2 * q20 + hb0)
    if gap > loose:
        return BOX_APART
    tight_apart = tight_apart or gap > tight
    gap = abs(t0 * r01 + t1 * r11 + t2 * r21) - (ha0 * q01 + ha1 * q11 + ha2 * q21 + hb1)
    if gap > loose:
        return BOX_APART
    tight_apart = tight_apart or gap > tight
    gap = abs(t0 * r02 + t1 * r12 + t2 * r22) - (ha0 * q02 + ha1 * q12 + ha2 * q22 + hb2)
    if gap > loose:
        return BOX_APART
    tight_apart = tight_apart or gap > tight

    # a_i x b_j: distance |t_i2 r_i1j - t_i1 r_i2j| (i1, i2 the next two axes after i, cyclically)
    p00, p01, p02 = q00 + _PAD, q01 + _PAD, q02 + _PAD
    p10, p11, p12 = q10 + _PAD, q11 + _PAD, q12 + _PAD
    p20, p21, p22 = q20 + _PAD, q21 + _PAD, q22 + _PAD
    s = _edge_state(t2, r10, t1, r20, ha1 * p20 + ha2 * p10 + hb1 * p02 + hb2 * p01, loose, tight, tight_apart)
    if s < 0:
        return BOX_APART
    s = _edge_state(t2, r11, t1, r21, ha1 * p21 + ha2 * p11 + hb2 * p00 + hb0 * p02, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t2, r12, t1, r22, ha1 * p22 + ha2 * p12 + hb0 * p01 + hb1 * p00, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t0, r20, t2, r00, ha2 * p00 + ha0 * p20 + hb1 * p12 + hb2 * p11, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t0, r21, t2, r01, ha2 * p01 + ha0 * p21 + hb2 * p10 + hb0 * p12, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t0, r22, t2, r02, ha2 * p02 + ha0 * p22 + hb0 * p11 + hb1 * p10, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t1, r00, t0, r10, ha0 * p10 + ha1 * p00 + hb1 * p22 + hb2 * p21, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t1, r01, t0, r11, ha0 * p11 + ha1 * p01 + hb2 * p20 + hb0 * p22, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    s = _edge_state(t1, r02, t0, r12, ha0 * p12 + ha1 * p02 + hb0 * p21 + hb1 * p20, loose, tight, s == 1)
    if s < 0:
        return BOX_APART
    return BOX_LOOSE if s == 1 else BOX_BOTH


@njit(cache=True, inline="always")
def boxes_apart(boxes, a, b, size, margin):
    """Whether boxes a and b are separated by more than `margin` along one of the 15 SAT axes: boxes_state
    with one margin (whose tight question then never arises)."""
    return boxes_state(boxes, a, b, size, margin, margin) == BOX_APART

