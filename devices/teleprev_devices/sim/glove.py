"""sim.glove: the simulated operator's right hand as a mocap glove stream (SMPL-X hand pose)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from teleprev.devices.contract import StreamSpec
from teleprev_devices.sim.device import NoiseBlock, SimDevice, TimingSettings
from teleprev_devices.sim.operator import shared_operator, task_mode
from teleprev.human.smplx import HAND_POSE_NAMES, hand_pose_from_angles
from teleprev.messages import JointSample
from teleprev.topics import device_topic


@dataclass
class GloveSettings(TimingSettings):
    rate_hz: float = 120.0
    latency_ms: float = 2.0
    jitter_ms: float = 0.3
    clock_offset_s: float = 1234.5
    clock_drift_ppm: float = 15.0
    task: str = ""  # "": the session's task (set per episode); "cycle": all five in turn; or a task name
    noise_rad: float = 0.002  # sensor noise (standard deviation) on every finger angle

    def __post_init__(self):
        super().__post_init__()
        task_mode(self.task)
        if self.noise_rad < 0:
            raise ValueError(f"noise_rad must be >= 0, got {self.noise_rad}")


class SimGlove(SimDevice):
    """JointSample of the 45 SMPL-X hand pose components on /glove/<name>/hand."""

    kind = "glove"
    Settings = GloveSettings

    def __init__(self, name, settings, context):
        super().__init__(name, settings, context)
        self.topic = device_topic("glove", name, "hand")
        self.operator = shared_operator(context, name, settings.seed, settings.task)
        self._noise = NoiseBlock(self._rng, settings.noise_rad, 30)

    def streams(self) -> list[StreamSpec]:
        return [StreamSpec(self.topic, "joints", self.settings.rate_hz)]

    def _acquire(self, true_ns: int):
        flexion, abduction = self.operator.hand_angles(self.operator.time_s(true_ns))
        if self.settings.noise_rad > 0:
            noise = self._noise.next()
            flexion, abduction = flexion + noise[:15], abduction + noise[15:]
        pose = hand_pose_from_angles(flexion, abduction).reshape(45)
        return [(self.topic, JointSample(0, HAND_POSE_NAMES, pose))]
