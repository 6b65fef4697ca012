"""Arm inverse kinematics in compiled code (teleprev.robot.ik.ArmIK), and the wrist-to-TCP target that
feeds it (teleprev.retarget.arm.ArmRetargeter): one call per pipeline step does both (arm_solve).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from teleprev.kernels.fk import FkTable, fk_into


class IkChain(NamedTuple):
    """The arm chain's joints as the solver takes them (after its FkTable)."""

    tip: int  # the tip link's row in the FK table
    tcp: np.ndarray  # (4, 4) the tool transform from the tip link
    joint_links: np.ndarray  # (n,) int64: each joint's child link row
    axes: np.ndarray  # (n, 3) each joint's axis in its child link's frame
    revolute: np.ndarray  # (n,) bool
    lower: np.ndarray  # (n,) joint limits
    upper: np.ndarray


class IkSettings(NamedTuple):
    position_tolerance: float  # metres
    rotation_tolerance: float  # radians
    max_iterations: int
    damping: float
    max_step: float  # radians per iteration, the largest joint step
    retry: bool  # a short-stepped second try from the start when the first does not converge


class Workspace(NamedTuple):
    """How the wrist's motion moves the TCP target (ArmRetargeter): rotated, scaled, clipped to a box."""

    m: np.ndarray  # (3, 3) the suit frame in the robot frame
    scale: float
    lo: np.ndarray  # (3,) the workspace box
    hi: np.ndarray

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


# Each kernel's parameters, a table standing for its fields in order (tests/kernels/test_tables.py).
SIGNATURES = {
    "ik_solve": ("target", "q_start", FkTable, IkChain, IkSettings),
    "arm_target_into": ("anchor_wrist", "anchor_tcp", "wrist", Workspace, "t"),
    "arm_solve": ("anchor_wrist", "anchor_tcp", "wrist", Workspace, "q_start", FkTable, IkChain, IkSettings),
}
