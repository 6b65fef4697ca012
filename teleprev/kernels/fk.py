"""Forward kinematics of a joint tree (fixed, revolute and prismatic joints, mimic joints included), in
compiled code: the link transforms of one configuration or of a batch.

The tables come from a RobotModel (teleprev.robot.compiled_kinematics.CompiledKinematics builds an
FkTable); each kernel takes the table's fields, in FkTable's order, after its own first arguments.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

# Joint kinds in the FK table.
FIXED, REVOLUTE, PRISMATIC = 0, 1, 2


class FkTable(NamedTuple):
    """A joint tree, links in parent-first order (row 0 the root)."""

    link_int: np.ndarray  # (L, 3) int64: parent row, joint-vector index of the driving joint, kind
    link_num: np.ndarray  # (L, 2) float64: multiplier and offset on that joint's value (mimic joints)
    link_terms: np.ndarray  # (L, 4, 3, 4) float64: the joint origin's top rows and the three terms (fk_into)



@njit(cache=True)
def fk_into(q, link_int, link_num, link_terms, world):
    """Link transforms (L, 4, 4) of one configuration into `world`.

    Links are in parent-first order, row 0 is the root. link_int (L, 3): parent, joint-vector index of
    the driving joint, kind. link_num (L, 2): multiplier and offset on that joint's value (mimic joints).
    link_terms (L, 4, 3, 4): the top three rows of the joint origin and of the three terms whose
    weighted sum gives the local transform: origin + sin(a) k1 + (1 - cos(a)) k2 + d slide.
    """
    n = link_int.shape[0]
    for r in range(4):
        for c in range(4):
            world[0, r, c] = 1.0 if r == c else 0.0
    local = np.empty((3, 4))
    for i in range(1, n):
        kind = link_int[i, 2]
        s = 0.0
        c1 = 0.0
        d = 0.0
        if kind != FIXED:
            v = q[link_int[i, 1]] * link_num[i, 0] + link_num[i, 1]
            if kind == REVOLUTE:
                s = np.sin(v)
                c1 = 1.0 - np.cos(v)
            else:
                d = v
        for r in range(3):
            for c in range(4):
                local[r, c] = (link_terms[i, 0, r, c] + s * link_terms[i, 1, r, c] + c1 * link_terms[i, 2, r, c]
                               + d * link_terms[i, 3, r, c])
        p = link_int[i, 0]
        for r in range(3):
            for c in range(4):
                acc = world[p, r, 0] * local[0, c] + world[p, r, 1] * local[1, c] + world[p, r, 2] * local[2, c]
                world[i, r, c] = acc + world[p, r, 3] if c == 3 else acc
        world[i, 3, 0] = 0.0
        world[i, 3, 1] = 0.0
        world[i, 3, 2] = 0.0
        world[i, 3, 3] = 1.0


@njit(cache=True)
def fk(q, link_int, link_num, link_terms):
    world = np.empty((link_int.shape[0], 4, 4))
    fk_into(q, link_int, link_num, link_terms, world)
    return world


@njit(cache=True)
def fk_batch(qs, link_int, link_num, link_terms):
    world = np.empty((qs.shape[0], link_int.shape[0], 4, 4))
    for k in range(qs.shape[0]):
        fk_into(qs[k], link_int, link_num, link_terms, world[k])
    return world


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {"fk_into": ("q", FkTable, "world"), "fk": ("q", FkTable), "fk_batch": ("qs", FkTable)}
