"""What sim.glove and sim.suit share: they stream the rig's one simulated operator, and their `task`
setting says what it does."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, TypeVar

from teleprev.devices import DeviceContext
from teleprev_devices.sim.device import NoiseBlock, SimDevice, TimingSettings
from teleprev_devices.sim.operator import shared_operator, task_mode
from teleprev_devices.sim.tasks import TASKS


@dataclass
class OperatorSettings(TimingSettings):
    # "": the session's task (set per episode); "cycle": all five in turn; or a task name.
    # Glove and suit must agree (one operator drives both), and on the seed.
    task: str = ""

    def __post_init__(self):
        super().__post_init__()
        task_mode(self.task)

    def episode_tasks(self) -> tuple[str, ...]:
        """The task labels an episode may carry (teleprev.rig.Rig.check_task): following the episode's task,
        the operator knows these five; with a fixed task or "cycle" it ignores the label, so any goes."""
        return TASKS if task_mode(self.task)[1] == "follow" else ()


OperatorT = TypeVar("OperatorT", bound=OperatorSettings)


class OperatorDevice(SimDevice[OperatorT]):
    """A sim device streaming the operator, with sensor noise: `noise` maps each setting that is a noise
    standard deviation to how many values it perturbs per sample."""

    noise: ClassVar[dict[str, int]] = {}

    def __init__(self, name: str, settings: OperatorT, context: DeviceContext):
        super().__init__(name, settings, context)
        self.operator = shared_operator(context, name, settings.seed, settings.task)
        self.noise_blocks = {
            key: NoiseBlock(self._rng, getattr(settings, key), dims) for key, dims in self.noise.items()
        }
