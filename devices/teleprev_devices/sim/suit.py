"""sim.suit: the simulated operator's right wrist as an IMU suit stream."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.devices.contract import StreamSpec
from teleprev_devices.sim.device import NoiseBlock, SimDevice, TimingSettings
from teleprev_devices.sim.operator import shared_operator, task_mode
from teleprev.messages import PoseSample
from teleprev.transforms import matrix_to_quat, rpy_to_matrix
from teleprev.topics import device_topic


@dataclass
class SuitSettings(TimingSettings):
    rate_hz: float = 60.0
    latency_ms: float = 5.0
    jitter_ms: float = 0.5
    clock_offset_s: float = -310.25
    clock_drift_ppm: float = -12.0
    task: str = ""  # must match the glove's (one operator drives both)
    noise_m: float = 0.0005  # sensor noise (standard deviation) on the wrist position
    noise_rad: float = 0.002  # and on its orientation

    def __post_init__(self):
        super().__post_init__()
        task_mode(self.task)
        if self.noise_m < 0 or self.noise_rad < 0:
            raise ValueError(f"noise_m and noise_rad must be >= 0, got {self.noise_m} and {self.noise_rad}")


class SimSuit(SimDevice):
    """PoseSample of the right wrist in the suit's world frame ("suit") on /suit/<name>/wrist."""

    kind = "suit"
    Settings = SuitSettings

    def __init__(self, name, settings, context):
        super().__init__(name, settings, context)
        self.topic = device_topic("suit", name, "wrist")
        self.operator = shared_operator(context, name, settings.seed, settings.task)
        self._position_noise = NoiseBlock(self._rng, settings.noise_m, 3)
        self._rotation_noise = NoiseBlock(self._rng, settings.noise_rad, 3)

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.topic, "pose", self.settings.rate_hz)]

    def _acquire(self, true_ns: int):
        s = self.operator.state(self.operator.time_s(true_ns))
        position, rotation = s.wrist_position, s.wrist_rotation
        if self.settings.noise_m > 0:
            position = position + self._position_noise.next()
        if self.settings.noise_rad > 0:
            rotation = rpy_to_matrix(*self._rotation_noise.next()) @ rotation  # a small random turn
        return [(self.topic, PoseSample(0, "suit", np.asarray(position, dtype=float), matrix_to_quat(rotation)))]
