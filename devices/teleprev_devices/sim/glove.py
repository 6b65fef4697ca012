"""sim.glove: the simulated operator's right (or left) hand as a mocap glove stream (SMPL-X hand pose)."""

from __future__ import annotations

from teleprev.devices import JointSample, body_mirror, smplx
from teleprev_devices.sim.device import timing
from teleprev_devices.sim.operated import OperatorDevice, OperatorSettings


@timing(rate_hz=120.0, latency_ms=2.0, jitter_ms=0.3, clock_offset_s=1234.5, clock_drift_ppm=15.0)
class GloveSettings(OperatorSettings):
    noise_rad: float = 0.002  # sensor noise (standard deviation) on every finger angle
    side: str = "right"  # "left": the operator's left hand, its pose mirrored from the right (teleprev/human/mirror.py)

    def __post_init__(self):
        super().__post_init__()
        if self.side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', got {self.side!r}")
        if self.noise_rad < 0:
            raise ValueError(f"noise_rad must be >= 0, got {self.noise_rad}")


class SimGlove(OperatorDevice[GloveSettings], kind="glove", stream="hand", payload="joints"):
    """JointSample of the 45 SMPL-X hand pose components on /glove/<name>/hand."""

    noise = {"noise_rad": 30}  # flexion and abduction of 15 joints

    def _acquire(self, true_ns: int) -> JointSample:
        flexion, abduction = self.operator.hand_angles(self.operator.time_s(true_ns))
        if self.settings.noise_rad > 0:
            noise = self.noise_blocks["noise_rad"].next()
            flexion, abduction = flexion + noise[:15], abduction + noise[15:]
        pose = smplx.hand_pose_from_angles(flexion, abduction).reshape(45)
        if self.settings.side == "left":
            pose = body_mirror.mirror_hand_pose(pose)
        return JointSample(0, smplx.HAND_POSE_NAMES, pose)
