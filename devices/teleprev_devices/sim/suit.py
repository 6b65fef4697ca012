"""sim.suit: the simulated operator's right (or left) wrist as an IMU suit stream."""

from __future__ import annotations

import numpy as np

from teleprev.devices import PoseSample, body_mirror, transforms
from teleprev_devices.sim.device import timing
from teleprev_devices.sim.operated import OperatorDevice, OperatorSettings


@timing(rate_hz=60.0, latency_ms=5.0, jitter_ms=0.5, clock_offset_s=-310.25, clock_drift_ppm=-12.0)
class SuitSettings(OperatorSettings):
    noise_m: float = 0.0005  # sensor noise (standard deviation) on the wrist position
    noise_rad: float = 0.002  # and on its orientation
    side: str = "right"  # "left": the operator's left wrist, mirrored from the right (teleprev/human/mirror.py)

    def __post_init__(self):
        super().__post_init__()
        if self.side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")
        if self.noise_m < 0 or self.noise_rad < 0:
            raise ValueError(f"noise_m and noise_rad must be >= 0, got {self.noise_m} and {self.noise_rad}")


class SimSuit(OperatorDevice[SuitSettings], kind="suit", stream="wrist", payload="pose"):
    """PoseSample of the right wrist in the suit's world frame ("suit") on /suit/<name>/wrist."""

    noise = {"noise_m": 3, "noise_rad": 3}  # position, and a small turn (roll, pitch, yaw)

    def _acquire(self, true_ns: int) -> PoseSample:
        s = self.operator.state(self.operator.time_s(true_ns))
        position, rotation = s.wrist_position, s.wrist_rotation
        if self.settings.side == "left":
            position, rotation = body_mirror.mirror_wrist(position, rotation)
        if self.settings.noise_m > 0:
            position = position + self.noise_blocks["noise_m"].next()
        if self.settings.noise_rad > 0:
            rotation = (
                transforms.rpy_to_matrix(*self.noise_blocks["noise_rad"].next()) @ rotation
            )  # a small random turn
        return PoseSample(0, "suit", np.asarray(position, dtype=float), transforms.matrix_to_quat(rotation))
