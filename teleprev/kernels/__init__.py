"""Every compiled (numba) kernel of teleprev, one module per concern, on the ground floor:

    fk          forward kinematics of a joint tree
    ik          arm inverse kinematics, and the wrist-to-TCP target that feeds it
    boxes       the separating-axis test of two boxes, two margins in one pass
    collision   self-collision of an all-box robot (spheres cull, boxes decide)
    swept       the swept check of a hand command's segment
    motion      the hand's acceleration cap and the arm generator's arithmetic around ruckig
    glove       a glove sample's decoding, checks, finger angles and retargeting
    mlp         CPN / CCN inference and the Corrector's CCN step
    correction  the Corrector's answer for one configuration: the check, the CCN step, its checks

Kernels take arrays and numbers only; the classes that use them build their tables (the NamedTuples
beside the kernels), and pass a table's fields in its order (`kernel(q, *table)`): a NamedTuple argument
itself costs numba about 6 us per call to type, several times a whole FK. tests/kernels/test_tables.py
checks that every kernel's parameters name the fields of the tables it takes, in order.

Importing this package compiles nothing: each kernel compiles on its first call and is cached on disk,
and `warm()` (scripts/setup.sh runs it) compiles every one of them for the types the classes pass.

The cache is keyed on the whole package. numba keys a cached kernel on its own source file only, so a
kernel that calls one in another module (the swept check calls the self-collision test, which calls the
box test and FK) would keep stale machine code after the callee's module changed. Here every kernel's
cache entry carries a hash of all of this package's sources instead (_PackageStamp): a change to any
module recompiles them all, and nothing else shares the key.
"""

from __future__ import annotations

import hashlib
import os

from numba.core import caching

_HERE = os.path.dirname(os.path.abspath(__file__))
_STAMP: list[bytes] = []  # computed once per process


def package_stamp() -> bytes:
    """sha256 over the names and contents of this package's modules."""
    if not _STAMP:
        h = hashlib.sha256()
        for name in sorted(os.listdir(_HERE)):
            if name.endswith(".py"):
                with open(os.path.join(_HERE, name), "rb") as f:
                    h.update(name.encode() + b"\0" + f.read() + b"\0")
        _STAMP.append(h.digest())
    return _STAMP[0]


class _PackageStamp:
    """A numba cache locator's source stamp for kernels of this package: the whole package's hash."""

    def get_source_stamp(self):
        return package_stamp()

    @classmethod
    def from_function(cls, py_func, py_file):
        if os.path.dirname(os.path.abspath(py_file)) != _HERE:
            return None  # not ours: numba's own locators take it
        return super().from_function(py_func, py_file)


class _UserProvided(_PackageStamp, caching.UserProvidedCacheLocator):
    pass


class _InTree(_PackageStamp, caching.InTreeCacheLocator):
    pass


class _UserWide(_PackageStamp, caching.UserWideCacheLocator):
    pass


if _UserProvided not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes[:0] = [_UserProvided, _InTree, _UserWide]


def warm() -> None:
    """Compile every kernel into numba's on-disk cache, or load it from there: scripts/setup.sh runs it, so
    that no record or eval pays the seconds of compiling, and eval's workers start with them loaded.

    Each kernel is called once with small tables of the types the classes build (contiguous float64 and
    int64 arrays, Python floats, ints and bools); tests/kernels/test_warm.py checks that building and
    stepping every sim rig's pipeline afterwards compiles or loads nothing more."""
    import numpy as np

    from teleprev.kernels import collision, correction, fk, glove, ik, mlp, motion, swept

    f64, i64 = np.float64, np.int64
    # FK: a root and two revolute joints about z, 0.1 m apart
    terms = np.zeros((3, 4, 3, 4))
    terms[:, 0, :, :3] = np.eye(3)
    terms[1:, 0, 0, 3] = 0.1
    terms[1:, 1] = [[0.0, -1.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]  # K
    terms[1:, 2] = [[-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]  # K^2
    table = fk.FkTable(np.array([[0, 0, fk.FIXED], [0, 0, fk.REVOLUTE], [1, 1, fk.REVOLUTE]], dtype=i64),
                       np.array([[1.0, 0.0]] * 3), terms)
    q = np.zeros(2)
    world = fk.fk(q, *table)
    fk.fk_into(q, *table, world)
    fk.fk_batch(np.zeros((2, 2)), *table)

    chain = ik.IkChain(2, np.eye(4), np.array([1, 2], dtype=i64), np.array([[0.0, 0.0, 1.0]] * 2),
                       np.ones(2, dtype=np.bool_), -np.ones(2), np.ones(2))
    settings = ik.IkSettings(5e-4, 5e-3, 5, 1e-6, 0.4, False)
    pose = world[2].copy()
    ik.ik_solve(pose, q, *table, *chain, *settings)
    space = ik.Workspace(np.eye(3), 1.0, -np.ones(3), np.ones(3))
    ik.arm_target_into(pose, pose, pose, *space, np.empty((4, 4)))
    ik.arm_solve(pose, pose, pose, *space, q, *table, *chain, *settings)

    # self-collision: one box on each moving link, one checked pair
    local = np.zeros((2, 3, 4))
    local[:, :, :3] = np.eye(3)
    boxes = collision.BoxTable(np.array([1, 2], dtype=i64), local, np.full((2, 4), 0.01),
                               np.array([[1, 0, 1], [2, 1, 2]], dtype=i64), np.array([[0.0, 0.0, 0.0, 0.02]] * 2),
                               np.array([[0, 1]], dtype=i64))
    for margins in (collision.Margins(1e-9, 1e-9), collision.Margins(1e-9, -1e-9)):
        collision.check_margins(q, *table, *boxes, *margins, False, np.zeros(2, dtype=np.bool_), np.empty(1, dtype=i64))
        collision.collides_margins(q, *table, *boxes, *margins)
        collision.pair_matrix_margins_world(world[None], *boxes, *margins)
        collision.first_colliding_margins(np.zeros((2, 2)), 0, *table, *boxes, *margins)

    shapes = swept.SweptShapes(boxes.shape_link, np.stack([local, local]), np.stack([boxes.shape_size] * 2),
                               boxes.links, np.stack([boxes.spheres] * 2), boxes.pairs)
    reach = swept.SweptTable(np.full((2, 2), 0.1), 0.0015, 0.0005)
    point = np.empty(2)
    q1 = q + 1e-3
    swept.swept_segment(q, q1, -1, 1, *reach, *table, *shapes, *margins, point)
    swept.swept_last_free(q, q1, 1, -1, *reach, *table, *shapes, *margins, point, np.empty(2))
    swept.swept_command(q, q1, q, q + 1.0, q - 1.0, q + 1.0, -1, -1, *reach, *table, *shapes, *margins, point)
    fingers = swept.Fingers(np.zeros(2, dtype=i64), np.zeros(2, dtype=i64), 1)
    swept.swept_slide(q, -1, q1, q, np.stack([q, q]), q1, 0.01, q + 1.0, q - 1.0, q + 1.0, 1, 10, *fingers, *reach,
                      *table, *shapes, *margins, point, np.empty((2, 2)))

    x = np.zeros(2)
    hand = motion.HandLimits(x - 1.0, x + 1.0, x + 1.0, x + 1.0, 0.8, True)
    for tracking in (True, False):
        motion.hand_command(x, x, tracking, x, motion.ESTIMATE_BLEND, x, x, 0.5, 0.01, 0.01, 1.0, *hand)
    plan = motion.arm_plan(x, x, x, motion.ESTIMATE_BLEND, x, x, 0.01, 0.5, 0.0, 0.01, 1.0,
                           *motion.ArmLimits(x + 1.0, x - 1.0, x + 1.0, x + 1.0))
    motion.arm_sample(plan[4], plan[5], np.zeros((3, 2)), plan[6], x - 1.0, x + 1.0, 0.02, 1e-6, 1e-5)
    motion.far_from_limits(x, x, x, x - 1.0, x + 1.0, x + 1.0, x + 1.0)
    motion.velocity_estimate(x, motion.ESTIMATE_BLEND, x, x, 0.01, 0.5)

    retarget = np.zeros((5, 2))
    retarget[glove.UPPER] = 1.0
    glove.prepare_rows(np.zeros((1, 45)), *glove.GloveTable(np.ones((2, 15)), np.array([8.41, -1.2, 2.7, 1.3, 1e-9]),
                                                            retarget))

    # two one-layer networks on two joints with two outputs (header, input index, layer, output pointers)
    def net(activation: int, noisy_or: int) -> mlp.Net:
        header = [1, 2, 2, 1, 2, activation, noisy_or, 2]
        return mlp.Net(np.array(header + [0, 1] + [0, 4, 2, 2] + [0, 1, 2] + [0, 1], dtype=i64),
                       np.ones(6, dtype=np.float32))

    cpn, ccn = net(mlp.RELU, 1), net(mlp.SILU, 0)
    rows = np.zeros((3, 2))
    limits = np.array([-1.0, -1.0, 1.0, 1.0, 0.1, 0.1], dtype=f64)
    mlp.slots(rows, *cpn)
    mlp.predicts_free(rows, *cpn, 2.0)
    mlp.propose(rows, *ccn, limits)
    step = mlp.CcnStep(*ccn, limits, *cpn, 2.0, 4)
    mlp.propose_shorten(rows, *step)
    correction.correct_one(q, q, *table, *boxes, *margins, *step, np.zeros(2, dtype=np.bool_), np.empty(1, dtype=i64),
                           np.empty(2))
