"""What sim.glove and sim.suit share: they stream the rig's one simulated operator, and their `task`
setting says what it does."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, TypeVar

from teleprev.devices import DeviceContext
from teleprev_devices.sim.device import NoiseBlock, SimDevice, TimingSettings
from teleprev_devices.sim.operator import shared_operator, task_mode


@dataclass
class OperatorSettings(TimingSettings):
    # "": the session's task (set per episode); "cycle": all five in turn; or a task name.
    # Glove and suit must agree (one operator drives both), and on the seed.
    task: str = ""

    def __post_init__(self):
        super().__post_init__()
        task_mode(self.task)


O = TypeVar("O", bound=OperatorSettings)


class OperatorDevice(SimDevice[O]):
    """A sim device streaming the operator, with sensor noise: `noise` maps each setting that is a noise
    standard deviation to how many values it perturbs per sample."""

    noise: ClassVar[dict[str, int]] = {}

    def __init__(self, name: str, settings: O, context: DeviceContext):
        super().__init__(name, settings, context)
        self.operator = shared_operator(context, name, settings.seed, settings.task)
        self.noise_blocks = {key: NoiseBlock(self._rng, getattr(settings, key), dims) for key, dims in self.noise.items()}
