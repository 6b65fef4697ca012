"""Compiled (numba) preparation of glove samples: the pipeline's per-sample arithmetic from the 45
axis-angle values to the effector's retargeted joints, for the live step and eval (Pipeline.compiled).

Per row, in one pass and in this order (the order of the numpy path, Pipeline._prepare_hand):
    decode      the 15 joints' axis-angle vectors, in HAND_POSE_NAMES order (the name lookup is Python's)
    checks      every value finite (else INVALID), every joint's rotation <= MAX_JOINT_ROTATION (else
                OUT_OF_RANGE)
    angles      angles_from_hand_pose (teleprev/human/smplx.py): the quaternion, turned into the joint
                frame, then the bone's direction as flexion and abduction; OUT_OF_RANGE too
                where flexion or abduction is beyond the human bounds. Older sessions read them abduction
                first, the twist about the bone taken off where above TWIST_NOISE
                (prepare_rows_abduction_first, angles_from_hand_pose_abduction_first)
    retarget    LeapRetargeter.from_angles: angle[source] * gain + offset, clipped to the joint limits
                (skipped for an effector that needs only the angles: a table with no columns)

The same row code runs for one sample (the live step) and for a session's samples (eval), and each row
depends on nothing but its own values, so a sample gets the same bits either way. The arithmetic follows
the numpy expressions but not bit for bit (libm's sin/cos/atan2 and the per-joint untwist may differ in
the last bits, tests/pipeline/test_hand_kernels.py bounds it), so it began a session format of its own. The
kernels that call each other live in this file only, so that the on-disk cache is invalidated with them.
Compiled on the first call and cached on disk (cache=True); warm(), run by scripts/setup.sh, fills the cache.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

OK, INVALID, OUT_OF_RANGE = 0, 1, 2  # per-row flags
FLAG_NAMES = ("", "glove_invalid", "glove_out_of_range")  # the pipeline's flag for each (HandInput.flag)

# limits: the plausibility bounds, in this order
MAX_ROTATION_SQ, MIN_FLEXION, MAX_FLEXION, MAX_ABDUCTION, TWIST_NOISE = range(5)
# table rows: the effector's retargeting, one column per joint
SOURCE, GAIN, OFFSET, LOWER, UPPER = range(5)


class GloveTable(NamedTuple):
    frames: np.ndarray  # (2, 15) cos and sin of each finger joint frame's turn about y
    limits: np.ndarray  # (5,) the plausibility bounds, indexed MAX_ROTATION_SQ .. TWIST_NOISE
    table: np.ndarray  # (5, n) the effector's retargeting, rows SOURCE .. UPPER (n = 0: angles only)


@njit(cache=True, inline="always")
def _clip(v, lo, hi):
    v = v if v > lo else lo  # np.maximum then np.minimum, as RobotModel.clip
    return v if v < hi else hi


@njit(cache=True, inline="always")
def _retarget_row(angles, table, out):
    for i in range(table.shape[1]):
        a = angles[int(table[SOURCE, i])]
        out[i] = _clip(a * table[GAIN, i] + table[OFFSET, i], table[LOWER, i], table[UPPER, i])


@njit(cache=True, inline="always")
def _checks(values, limits):
    """INVALID where a value is not finite, OUT_OF_RANGE where a joint's rotation is beyond the bound, else OK."""
    n = values.shape[0]
    for k in range(n):
        if not math.isfinite(values[k]):
            return INVALID
    for j in range(15):
        vx, vy, vz = values[3 * j], values[3 * j + 1], values[3 * j + 2]
        if vx * vx + vy * vy + vz * vz > limits[MAX_ROTATION_SQ]:
            return OUT_OF_RANGE
    return OK


@njit(cache=True, inline="always")
def _prepare_row(values, frames, limits, table, angles, q):
    """One glove sample: its flag, and where OK its angles [flexion(15), abduction(15)] and joints. The
    angles are the bone's direction in the joint frame, flexion first (smplx.angles_from_hand_pose)."""
    flag = _checks(values, limits)
    if flag != OK:
        return flag
    for j in range(15):
        vx, vy, vz = values[3 * j], values[3 * j + 1], values[3 * j + 2]
        angle = math.sqrt(vx * vx + vy * vy + vz * vz)
        half = 0.5 * angle
        scale = math.sin(half) / angle if angle > 1e-12 else 0.5
        w = math.cos(half)
        x0, y, z0 = vx * scale, vy * scale, vz * scale
        c, s = frames[0, j], frames[1, j]
        x = c * x0 - s * z0
        z = s * x0 + c * z0
        m00 = 1.0 - 2.0 * (y * y + z * z)
        m10 = 2.0 * (x * y + z * w)
        m20 = 2.0 * (x * z - y * w)
        flexion = math.atan2(m10, m00)
        abduction = math.atan2(-m20, math.sqrt(m00 * m00 + m10 * m10))
        angles[j] = flexion
        angles[15 + j] = abduction
        if flexion > limits[MAX_FLEXION] or flexion < limits[MIN_FLEXION] or abs(abduction) > limits[MAX_ABDUCTION]:
            flag = OUT_OF_RANGE
    if flag == OK:
        _retarget_row(angles, table, q)
    return flag


@njit(cache=True, inline="always")
def _prepare_row_abduction_first(values, frames, limits, table, angles, q):
    """_prepare_row as older sessions computed it (smplx.angles_from_hand_pose_abduction_first):
    the twist about the bone taken off, then abduction first. Kept unchanged."""
    flag = _checks(values, limits)
    if flag != OK:
        return flag
    for j in range(15):
        vx, vy, vz = values[3 * j], values[3 * j + 1], values[3 * j + 2]
        angle = math.sqrt(vx * vx + vy * vy + vz * vz)
        half = 0.5 * angle
        scale = math.sin(half) / angle if angle > 1e-12 else 0.5
        w = math.cos(half)
        x0, y, z0 = vx * scale, vy * scale, vz * scale
        c, s = frames[0, j], frames[1, j]
        x = c * x0 - s * z0
        z = s * x0 + c * z0
        # the twist about the bone (the one nearer zero of the two that point the bone alike), taken off
        m11 = 1.0 - 2.0 * (x * x + z * z)
        m12 = 2.0 * (y * z - x * w)
        twist = math.atan2(-m12, m11)
        if twist > 0.5 * math.pi:
            twist -= math.pi
        elif twist < -0.5 * math.pi:
            twist += math.pi
        if abs(twist) > limits[TWIST_NOISE]:
            tc, ts = math.cos(0.5 * twist), math.sin(0.5 * twist)
            w, x, y, z = w * tc + x * ts, x * tc - w * ts, y * tc - z * ts, z * tc + y * ts
        flexion = math.atan2(2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z))
        abduction = math.atan2(2.0 * (x * z + y * w), 1.0 - 2.0 * (x * x + y * y))
        angles[j] = flexion
        angles[15 + j] = abduction
        if flexion > limits[MAX_FLEXION] or flexion < limits[MIN_FLEXION] or abs(abduction) > limits[MAX_ABDUCTION]:
            flag = OUT_OF_RANGE
    if flag == OK:
        _retarget_row(angles, table, q)
    return flag


@njit(cache=True)
def prepare_rows(values, frames, limits, table):
    """Glove samples (N, 45) -> (flags (N,), angles (N, 30) [flexion, abduction], joints (N, table columns)).

    frames: (2, 15) cos and sin of each joint frame's turn about y; limits: the bounds above; table: the
    retargeting (5, n). Angles where the flag is INVALID or OUT_OF_RANGE, and joints where it is not OK,
    are left zero."""
    rows = values.shape[0]
    flags = np.empty(rows, dtype=np.int64)
    angles = np.zeros((rows, 30))
    q = np.zeros((rows, table.shape[1]))
    for r in range(rows):
        flags[r] = _prepare_row(values[r], frames, limits, table, angles[r], q[r])
    return flags, angles, q


@njit(cache=True)
def prepare_rows_abduction_first(values, frames, limits, table):
    """prepare_rows with the reading of older sessions (_prepare_row_abduction_first)."""
    rows = values.shape[0]
    flags = np.empty(rows, dtype=np.int64)
    angles = np.zeros((rows, 30))
    q = np.zeros((rows, table.shape[1]))
    for r in range(rows):
        flags[r] = _prepare_row_abduction_first(values[r], frames, limits, table, angles[r], q[r])
    return flags, angles, q


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {"prepare_rows": ("values", GloveTable), "prepare_rows_abduction_first": ("values", GloveTable)}
