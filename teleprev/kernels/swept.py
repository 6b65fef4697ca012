"""Compiled (numba) kernels for the per-step robot arithmetic: forward kinematics of a joint tree and
the exact self-collision test of box geometry.

Kernels take arrays and numbers only; CompiledKinematics and CompiledSelfCollisionChecker build the
tables from a RobotModel. Each kernel compiles on its first call and is cached on disk (numba
`cache=True`), never at import: `teleprev.pipeline.compiled.warm()`, run by scripts/setup.sh,
fills the cache so that no record or eval pays the compile.

All kernels live in this one file on purpose: numba invalidates a cached kernel when its own source
file changes, not when a kernel it calls in another file does.

Box-box test: the separating-axis theorem, exact for two boxes with 15 candidate axes (3 face normals
of each box and the 9 cross products of their edges). A pair counts as apart only when some axis
separates it by more than `margin`; `MARGIN` (1 nm) makes every rounding difference against another
implementation (FCL) fall on the "colliding" side. Cross products of nearly parallel edges are close to
zero vectors, where rounding alone could make 0 > 0 true; padding |R| by `_PAD` keeps such an axis from
ever separating a pair that the face axes do not (it can only err towards "colliding").
"""

from __future__ import annotations

import numpy as np
from numba import njit

MARGIN = 1e-9  # metres: boxes closer than this along every axis count as touching
_PAD = 1e-12  # added to |R| for the edge-edge axes (see the module docstring)

# Joint kinds in the FK table.
FIXED, REVOLUTE, PRISMATIC = 0, 1, 2


# ---- forward kinematics ------------------------------------------------------------------------
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


# ---- arm inverse kinematics (teleprev.robot.ik.ArmIK with compiled=True) ------------------------
# ArmIK._solve's algorithm, step for step: damped least squares on the 6-D pose error from a clipped warm
# start, damping lam2 = damping + 1e-2 |err|^2, joints pinned at a limit and pushed outwards taken out of
# the step, the step capped at max_step, every iterate clipped to the limits, the stall rule, and the
# short-stepped retry. The 6x6 system is solved by Cholesky (it is symmetric positive definite: lam2 > 0),
# so the last bits differ from numpy's LU; the same inputs always give the same bits.
IK_STALL = 0.98  # teleprev.robot.ik._STALL


@njit(cache=True, inline="always")
def _clip_to(v, lo, hi):
    """v clipped to [lo, hi] for one value: np.minimum(np.maximum(v, lo), hi) (NaN stays NaN, as in numpy)
    except for the sign of a zero: where v and a bound are zeros of opposite sign (they compare equal) it
    returns v, numpy the bound (_clip_to(-0.0, 0.0, 1.0) is -0.0, numpy's 0.0). Recorded sessions depend
    on these exact values: keep the comparisons as they are."""
    v = lo if v < lo else v
    return hi if v > hi else v


@njit(cache=True)
def rotation_error_into(target, pose, out):
    """transforms.rotation_error(target[:3, :3], pose[:3, :3]) into out (3,): the rotation vector (world
    frame) that turns pose's rotation into target's (matrix_to_axis_angle of target R @ pose R^T)."""
    r = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r[i, j] = target[i, 0] * pose[j, 0] + target[i, 1] * pose[j, 1] + target[i, 2] * pose[j, 2]
    cos = (r[0, 0] + r[1, 1] + r[2, 2] - 1.0) / 2.0
    cos = min(1.0, max(-1.0, cos))
    angle = np.arccos(cos)
    w0 = r[2, 1] - r[1, 2]
    w1 = r[0, 2] - r[2, 0]
    w2 = r[1, 0] - r[0, 1]
    if angle < 1e-7:
        out[0], out[1], out[2] = 0.5 * w0, 0.5 * w1, 0.5 * w2
    elif np.pi - angle > 1e-4:
        f = angle / (2.0 * np.sin(angle))
        out[0], out[1], out[2] = w0 * f, w1 * f, w2 * f
    else:  # near pi: the axis is the dominant column of (R + I) / 2
        i = 0
        for k in range(1, 3):
            if r[k, k] > r[i, i]:
                i = k
        d = np.sqrt(max((r[i, i] + 1.0) / 2.0, 1e-300))
        a0 = (r[0, i] + (1.0 if i == 0 else 0.0)) / 2.0 / d
        a1 = (r[1, i] + (1.0 if i == 1 else 0.0)) / 2.0 / d
        a2 = (r[2, i] + (1.0 if i == 2 else 0.0)) / 2.0 / d
        if w0 * a0 + w1 * a1 + w2 * a2 < 0:
            a0, a1, a2 = -a0, -a1, -a2
        out[0], out[1], out[2] = a0 * angle, a1 * angle, a2 * angle


@njit(cache=True)
def _dls_step(jac, err, lam2, dq):
    """dq = jac^T (jac jac^T + lam2 I)^-1 err, the 6x6 system by Cholesky (A = L L^T)."""
    n = jac.shape[1]
    a = np.empty((6, 6))
    for i in range(6):
        for j in range(i + 1):
            s = 0.0
            for k in range(n):
                s += jac[i, k] * jac[j, k]
            a[i, j] = s
        a[i, i] += lam2
    for j in range(6):  # in place: the lower triangle becomes L
        s = a[j, j]
        for k in range(j):
            s -= a[j, k] * a[j, k]
        d = np.sqrt(s)
        a[j, j] = d
        for i in range(j + 1, 6):
            s = a[i, j]
            for k in range(j):
                s -= a[i, k] * a[j, k]
            a[i, j] = s / d
    y = np.empty(6)
    for i in range(6):  # L y = err
        s = err[i]
        for k in range(i):
            s -= a[i, k] * y[k]
        y[i] = s / a[i, i]
    for i in range(5, -1, -1):  # L^T x = y
        s = y[i]
        for k in range(i + 1, 6):
            s -= a[k, i] * y[k]
        y[i] = s / a[i, i]
    for k in range(n):
        s = 0.0
        for i in range(6):
            s += jac[i, k] * y[i]
        dq[k] = s


@njit(cache=True)
def _ik_try(target, q_start, max_step, link_int, link_num, link_terms, tip, tcp, joint_links, axes, revolute,
            lower, upper, position_tolerance, rotation_tolerance, max_iterations, damping, world, q):
    """One damped least-squares run (ArmIK._solve) into q: (converged, iterations, position and rotation error)."""
    n = q_start.shape[0]
    for k in range(n):
        q[k] = _clip_to(q_start[k], lower[k], upper[k])
    pose = np.empty((3, 4))
    e_rot = np.empty(3)
    err = np.empty(6)
    jac = np.empty((6, n))
    free = np.empty((6, n))
    dq = np.empty(n)
    pinned = np.empty(n, dtype=np.bool_)
    pos_err = np.inf
    rot_err = np.inf
    last = np.inf
    for it in range(max_iterations + 1):
        fk_into(q, link_int, link_num, link_terms, world)
        for r in range(3):  # pose = world[tip] @ tcp (top rows)
            for c in range(4):
                pose[r, c] = (world[tip, r, 0] * tcp[0, c] + world[tip, r, 1] * tcp[1, c]
                              + world[tip, r, 2] * tcp[2, c] + world[tip, r, 3] * tcp[3, c])
        rotation_error_into(target, pose, e_rot)
        for r in range(3):
            err[r] = target[r, 3] - pose[r, 3]
            err[r + 3] = e_rot[r]
        pos_err = np.sqrt(err[0] * err[0] + err[1] * err[1] + err[2] * err[2])
        rot_err = np.sqrt(err[3] * err[3] + err[4] * err[4] + err[5] * err[5])
        if pos_err <= position_tolerance and rot_err <= rotation_tolerance:
            return True, it, pos_err, rot_err
        # stalled (a joint pinned at its limit, an unreachable target): more iterations won't help
        progress = pos_err / position_tolerance + rot_err / rotation_tolerance
        if it == max_iterations or progress > IK_STALL * last:
            break
        last = progress
        for k in range(n):  # jacobian: revolute axis x lever and axis; prismatic axis and 0
            f = world[joint_links[k]]
            ax = f[0, 0] * axes[k, 0] + f[0, 1] * axes[k, 1] + f[0, 2] * axes[k, 2]
            ay = f[1, 0] * axes[k, 0] + f[1, 1] * axes[k, 1] + f[1, 2] * axes[k, 2]
            az = f[2, 0] * axes[k, 0] + f[2, 1] * axes[k, 1] + f[2, 2] * axes[k, 2]
            if revolute[k]:
                lx = pose[0, 3] - f[0, 3]
                ly = pose[1, 3] - f[1, 3]
                lz = pose[2, 3] - f[2, 3]
                jac[0, k], jac[1, k], jac[2, k] = ay * lz - az * ly, az * lx - ax * lz, ax * ly - ay * lx
                jac[3, k], jac[4, k], jac[5, k] = ax, ay, az
            else:
                jac[0, k], jac[1, k], jac[2, k] = ax, ay, az
                jac[3, k], jac[4, k], jac[5, k] = 0.0, 0.0, 0.0
        e2 = 0.0
        for r in range(6):
            e2 += err[r] * err[r]
        lam2 = damping + 1e-2 * e2
        _dls_step(jac, err, lam2, dq)
        # joints pinned at a limit and pushed further out leave the step; the others make up for them
        any_pinned = False
        for k in range(n):
            pinned[k] = (q[k] <= lower[k] + 1e-9 and dq[k] < 0) or (q[k] >= upper[k] - 1e-9 and dq[k] > 0)
            any_pinned = any_pinned or pinned[k]
        if any_pinned:
            for k in range(n):
                for r in range(6):
                    free[r, k] = 0.0 if pinned[k] else jac[r, k]
            _dls_step(free, err, lam2, dq)
        biggest = 0.0
        for k in range(n):
            a = abs(dq[k])
            if a > biggest or a != a:  # NaN wins, as in np.max
                biggest = a
        if biggest > max_step:
            s = max_step / biggest
            for k in range(n):
                dq[k] *= s
        for k in range(n):
            q[k] = _clip_to(q[k] + dq[k], lower[k], upper[k])
    return False, max_iterations, pos_err, rot_err


@njit(cache=True)
def ik_solve(target, q_start, link_int, link_num, link_terms, tip, tcp, joint_links, axes, revolute, lower, upper,
             position_tolerance, rotation_tolerance, max_iterations, damping, max_step, retry):
    """ArmIK.solve: (q, converged, iterations, position error, rotation error). target (4, 4) the TCP pose
    wanted; the FK tables are the arm chain's (CompiledKinematics), tip its link row, tcp (4, 4) the tool
    transform; joint_links, axes, revolute: each joint's child link row, axis and kind."""
    world = np.empty((link_int.shape[0], 4, 4))
    q = np.empty(q_start.shape[0])
    ok, it, pe, re = _ik_try(target, q_start, max_step, link_int, link_num, link_terms, tip, tcp, joint_links, axes,
                             revolute, lower, upper, position_tolerance, rotation_tolerance, max_iterations, damping,
                             world, q)
    if not ok and retry:
        # short steps from the start when a long first step landed a joint on its limit in a local minimum
        q2 = np.empty(q_start.shape[0])
        ok2, it2, pe2, re2 = _ik_try(target, q_start, max_step / 8, link_int, link_num, link_terms, tip, tcp,
                                     joint_links, axes, revolute, lower, upper, position_tolerance,
                                     rotation_tolerance, max_iterations, damping, world, q2)
        if ok2 or pe2 < pe:
            return q2, ok2, it2, pe2, re2
    return q, ok, it, pe, re


@njit(cache=True)
def arm_target_into(anchor_wrist, anchor_tcp, wrist, m, scale, lo, hi, t):
    """ArmRetargeter.target into t (4, 4): the anchor's TCP moved by the wrist's motion since the anchor
    (rotated into the robot frame by m, scaled, clipped to the box [lo, hi]); returns whether it clipped."""
    d = np.empty(3)
    for r in range(3):
        d[r] = wrist[r, 3] - anchor_wrist[r, 3]
    clipped = False
    for r in range(3):
        desired = anchor_tcp[r, 3] + scale * (m[r, 0] * d[0] + m[r, 1] * d[1] + m[r, 2] * d[2])
        v = _clip_to(desired, lo[r], hi[r])
        t[r, 3] = v
        clipped = clipped or v != desired
    # R = m @ R(W) @ R(W0)^T @ m^T @ R(T0), left to right as numpy
    a = np.empty((3, 3))
    b = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            a[i, j] = m[i, 0] * wrist[0, j] + m[i, 1] * wrist[1, j] + m[i, 2] * wrist[2, j]
    for i in range(3):
        for j in range(3):
            b[i, j] = a[i, 0] * anchor_wrist[j, 0] + a[i, 1] * anchor_wrist[j, 1] + a[i, 2] * anchor_wrist[j, 2]
    for i in range(3):
        for j in range(3):
            a[i, j] = b[i, 0] * m[j, 0] + b[i, 1] * m[j, 1] + b[i, 2] * m[j, 2]
    for i in range(3):
        for j in range(3):
            t[i, j] = a[i, 0] * anchor_tcp[0, j] + a[i, 1] * anchor_tcp[1, j] + a[i, 2] * anchor_tcp[2, j]
    t[3, 0], t[3, 1], t[3, 2], t[3, 3] = 0.0, 0.0, 0.0, 1.0
    return clipped


@njit(cache=True)
def arm_solve(anchor_wrist, anchor_tcp, wrist, m, scale, lo, hi, q_start, link_int, link_num, link_terms, tip, tcp,
              joint_links, axes, revolute, lower, upper, position_tolerance, rotation_tolerance, max_iterations,
              damping, max_step, retry):
    """ArmRetargeter.solve: arm_target_into, then ik_solve: (q, converged, iterations, position error,
    rotation error, clipped) in one call."""
    t = np.empty((4, 4))
    clipped = arm_target_into(anchor_wrist, anchor_tcp, wrist, m, scale, lo, hi, t)
    q, ok, it, pe, re = ik_solve(t, q_start, link_int, link_num, link_terms, tip, tcp, joint_links, axes, revolute,
                                 lower, upper, position_tolerance, rotation_tolerance, max_iterations, damping,
                                 max_step, retry)
    return q, ok, it, pe, re, clipped


# ---- boxes -------------------------------------------------------------------------------------
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


# ---- self-collision ----------------------------------------------------------------------------
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


# ---- swept check of a hand command's segment (teleprev/pipeline/swept.py) ------------------------
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

    Returns (answer, cache, clear). answer SWEPT_FREE / SWEPT_COLLIDES: decided without FCL; any other:
    the caller runs the two checks one by one. q0_clear / q1_clear: their clearance as the caller's cache
    knows it (-1: not known). cache, clear: the last clearance check, as SweptCheck.clear's cache would
    hold it after the two checks: 0 none, 1 q0, 2 q1, 3 the end point left in `point`; clear its answer.
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
        return answer, 0, 0
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
        return answer, cache, clear
    answer, k, c1, end = _swept(q1, stop, q1_clear, 1, reach, spacing, start_step, link_int, link_num, link_terms,
                                shape_link, shape_local, shape_size, links, spheres, pairs, loose, tight, world,
                                hits, labels, index, point)
    if answer > SWEPT_FREE:
        return answer, 0, 0
    if end >= 0:
        cache, clear = 3, end
    elif k >= 0 and spacing > 0:
        cache, clear = 2, c1
    return answer, cache, clear
