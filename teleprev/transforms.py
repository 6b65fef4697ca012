"""Small rigid-transform helpers on numpy arrays (rotation matrices, quaternions as x y z w)."""

from __future__ import annotations

import math

import numpy as np


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF convention: R = Rz(yaw) @ Ry(pitch) @ Rx(roll)."""
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def make_transform(rotation: np.ndarray | None = None, translation=None) -> np.ndarray:
    t = np.eye(4)
    if rotation is not None:
        t[:3, :3] = rotation
    if translation is not None:
        t[:3, 3] = translation
    return t


def axis_angle_to_matrix(axis_angle: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) to matrices (..., 3, 3) by Rodrigues' formula."""
    v = np.asarray(axis_angle, dtype=float)
    theta = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = np.where(theta > 1e-12, theta, 1.0)
    k = v / safe
    kx, ky, kz = k[..., 0], k[..., 1], k[..., 2]
    zero = np.zeros_like(kx)
    kmat = np.stack([zero, -kz, ky, kz, zero, -kx, -ky, kx, zero], axis=-1).reshape(v.shape[:-1] + (3, 3))
    s = np.sin(theta)[..., None]
    c = np.cos(theta)[..., None]
    eye = np.broadcast_to(np.eye(3), kmat.shape)
    return eye + s * kmat + (1.0 - c) * (kmat @ kmat)


def matrix_to_axis_angle(r: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) to rotation vector (3,), stable near 0 and pi."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = r.tolist()
    cos = min(1.0, max(-1.0, (r00 + r11 + r22 - 1.0) / 2.0))
    angle = math.acos(cos)
    w = np.array([r21 - r12, r02 - r20, r10 - r01])
    if angle < 1e-7:
        return 0.5 * w
    if math.pi - angle > 1e-4:
        return w * (angle / (2.0 * math.sin(angle)))
    # Near pi: the axis is the dominant column of (R + I) / 2.
    m = (r + np.eye(3)) / 2.0
    i = int(np.argmax(np.diag(m)))
    axis = m[:, i] / math.sqrt(max(m[i, i], 1e-300))
    if np.dot(w, axis) < 0:
        axis = -axis
    return axis * angle


def _rotation_rows(x: float, y: float, z: float, w: float) -> list[list[float]]:
    """The rotation matrix of quaternion x y z w (normalised first), as three rows of floats."""
    n = 1.0 / math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x * n, y * n, z * n, w * n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def pose_matrix(position, quaternion) -> np.ndarray:
    """The 4x4 homogeneous transform of a position (3,) and a quaternion (4,) x y z w (normalised first)."""
    r = _rotation_rows(*np.asarray(quaternion, dtype=float).tolist())
    x, y, z = np.asarray(position, dtype=float).tolist()
    return np.array([[*r[0], x], [*r[1], y], [*r[2], z], [0.0, 0.0, 0.0, 1.0]])


def quat_to_matrix(q) -> np.ndarray:
    """Quaternion(s) (..., 4) as x y z w to rotation matrices (..., 3, 3); normalises first."""
    q = np.asarray(q, dtype=float)
    if q.shape == (4,):  # one quaternion: plain floats are several times faster than array operations
        return np.array(_rotation_rows(*q.tolist()))
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
            2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
            2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y),
        ],
        axis=-1,
    )
    return m.reshape(q.shape[:-1] + (3, 3))


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) to quaternion x y z w with w >= 0."""
    m = np.asarray(r, dtype=float)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [(m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s, (m[2, 1] - m[1, 2]) / s]
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s, (m[0, 2] - m[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s, (m[1, 0] - m[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0 else q


def rotation_error(r_target: np.ndarray, r_current: np.ndarray) -> np.ndarray:
    """Rotation vector (world frame) that turns r_current into r_target."""
    return matrix_to_axis_angle(r_target @ r_current.T)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (..., 4) as x y z w."""
    ax, ay, az, aw = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bx, by, bz, bw = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
        axis=-1,
    )


def quat_from_axis_angle(axis_angle: np.ndarray) -> np.ndarray:
    v = np.asarray(axis_angle, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    scale = np.where(angle > 1e-12, np.sin(half) / np.where(angle > 1e-12, angle, 1.0), 0.5)
    return np.concatenate([v * scale, np.cos(half)], axis=-1)


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Quaternions (..., 4) x y z w to rotation vectors (..., 3), taking the short way round."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(q[..., 3:4] < 0, -q, q)
    v, w = q[..., :3], q[..., 3]
    s = np.linalg.norm(v, axis=-1)
    angle = 2.0 * np.arctan2(s, w)
    scale = np.where(s > 1e-12, angle / np.where(s > 1e-12, s, 1.0), 2.0)
    return v * scale[..., None]
