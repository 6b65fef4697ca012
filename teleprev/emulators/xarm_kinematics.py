"""The emulated xArm's body: the joint limits the SDK enforces for the arm's series, and the TCP pose by
forward kinematics of our URDF (inverse kinematics for set_position).

The pose is UFactory's convention: x, y, z in mm and roll, pitch, yaw in rad of R = Rz(yaw) Ry(pitch) Rx(roll);
at the zero pose the flange is at [207, 0, 112] mm, as UFactory gives the xArm6's initial position.
"""

from __future__ import annotations

import math

import numpy as np

TWO_PI = 2 * math.pi
# xarm/core/config/x_config.py XCONF.Robot.JOINT_LIMITS: (axis, series from XI1305 on) -> per-joint (low, high)
JOINT_TABLE = {
    (6, False): ((-TWO_PI, TWO_PI), (-2.059488, 2.094395), (-3.92699, 0.191986), (-TWO_PI, TWO_PI),
                 (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (6, True): ((-TWO_PI, TWO_PI), (-2.042035, 2.024581), (-3.822271, 0.174532), (-TWO_PI, TWO_PI),
                (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (7, False): ((-TWO_PI, TWO_PI), (-2.059488, 2.094395), (-TWO_PI, TWO_PI), (-0.191986, 3.92699),
                 (-TWO_PI, TWO_PI), (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
    (7, True): ((-TWO_PI, TWO_PI), (-2.042035, 2.024581), (-TWO_PI, TWO_PI), (-0.10472, 3.92699),
                (-TWO_PI, TWO_PI), (-1.692969, math.pi), (-TWO_PI, TWO_PI)),
}


def joint_table(dof: int, series: int) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) the SDK enforces: an SN from XI1305 up to 8500 uses the "_1305" row (x3/xarm.py
    _is_out_of_joint_range)."""
    table = np.array(JOINT_TABLE[dof, 1305 <= series < 8500])
    return table[:, 0], table[:, 1]


def rpy_from_matrix(r: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw of R = Rz(yaw) Ry(pitch) Rx(roll), the xArm's TCP orientation convention."""
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    return math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])


class ArmKinematics:
    """Forward and inverse kinematics of the xArm's joint1..jointN (our URDF, its flange link_eef)."""

    def __init__(self, dof: int):
        from teleprev.robot.model import load_robot

        self.model = load_robot(f"xarm{dof}")
        self.joint_index = self.model.indices(tuple(f"joint{i}" for i in range(1, dof + 1)))
        self.dof = dof
        self._ik = None

    def velocity_limit(self) -> np.ndarray:
        return self.model.velocity_limit[self.joint_index]  # 180 deg/s per joint (xArm specifications)

    def flange(self, q: np.ndarray) -> np.ndarray:
        """The flange's 4x4 pose (m) at joint angles q."""
        full = self.model.neutral()
        full[self.joint_index] = q
        return self.model.fk(full).matrix("link_eef")

    def pose(self, q: np.ndarray) -> list[float]:
        """The TCP pose as the box reports it: x, y, z in mm, roll, pitch, yaw in rad."""
        flange = self.flange(q)
        return [*(flange[:3, 3] * 1000.0), *rpy_from_matrix(flange[:3, :3])]

    def pose_axis_angle(self, q: np.ndarray) -> list[float]:
        """The TCP pose with its orientation as an axis-angle vector (register 91)."""
        from teleprev.transforms import matrix_to_axis_angle

        flange = self.flange(q)
        return [*(flange[:3, 3] * 1000.0), *matrix_to_axis_angle(flange[:3, :3])]

    def solve(self, pose, q_start: np.ndarray) -> np.ndarray | None:
        """Joints for a TCP pose (mm, rad), by our IK from q_start; None where it does not reach."""
        from teleprev.robot.ik import ArmIK
        from teleprev.transforms import make_transform, rpy_to_matrix

        if self._ik is None:
            self._ik = ArmIK(self.model, "link_eef")
        target = make_transform(rpy_to_matrix(*pose[3:6]), np.array(pose[:3]) / 1000.0)
        full = self.model.neutral()
        full[self.joint_index] = q_start
        result = self._ik.solve(target, full[:len(self._ik.joint_names)])
        return np.asarray(result.q)[:self.dof] if result.converged else None
