"""What the real actuators (xarm.arm, leap.hand) check on every command before it leaves the host.

The pipeline's command guard already keeps commands inside the joint limits; this is the second line
(defense in depth): a command that names unknown joints, has a non-finite value or lies outside the
URDF's limits is refused with a DeviceError, counted, and never sent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample

_TOLERANCE = 1e-9  # rad: round-off of a command computed exactly at a limit


@dataclass
class JointLimits:
    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray

    @classmethod
    def from_urdf(cls, robot: str, names: tuple[str, ...], where: str) -> JointLimits:
        from teleprev.robot.model import load_robot

        model = load_robot(robot)
        missing = [n for n in names if n not in model.joint_index]
        if missing:
            raise ConfigError(f"robot {model.name!r} has no joints {', '.join(missing)} "
                              f"(its joints: {', '.join(model.joint_names)})", where)
        idx = model.indices(names)
        return cls(names, model.lower[idx].copy(), model.upper[idx].copy())

    def target(self, command: JointSample, previous: np.ndarray, where: str) -> np.ndarray:
        """The full joint vector the command asks for (joints it leaves out keep `previous`), or a
        DeviceError saying why it is refused."""
        index = {n: i for i, n in enumerate(self.names)}
        unknown = [n for n in command.names if n not in index]
        if unknown:
            raise DeviceError(f"command refused: unknown joints {unknown} (expected {', '.join(self.names)})", where)
        positions = np.asarray(command.positions, dtype=float)
        if positions.shape != (len(command.names),):
            raise DeviceError(f"command refused: {positions.shape} positions for {len(command.names)} names", where)
        if not np.all(np.isfinite(positions)):
            bad = [n for n, v in zip(command.names, positions) if not np.isfinite(v)]
            raise DeviceError(f"command refused: non-finite positions for {', '.join(bad)}", where)
        target = np.array(previous, dtype=float)
        target[[index[n] for n in command.names]] = positions
        outside = (target < self.lower - _TOLERANCE) | (target > self.upper + _TOLERANCE)
        if outside.any():
            detail = "; ".join(f"{n}={v:.4f} not in [{lo:.4f}, {hi:.4f}]" for n, v, lo, hi, o in
                               zip(self.names, target, self.lower, self.upper, outside) if o)
            raise DeviceError(f"command refused: outside the joint limits: {detail}", where)
        return target
