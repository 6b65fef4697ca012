"""The driver of the pipelines that made their commands at each step (formats 1 to 3).

Its steps' commands are recorded with their targets, at the step's time; mode switches go to the pipeline
alone (there is no planner to tell); and the arm's state samples run idle steps, which brake moving
commands once the trigger device has gone quiet (a servo-mode xArm holds its last target, so commands
that simply stopped would be an instant freeze).
"""

from __future__ import annotations

import numpy as np

from teleprev import topics
from teleprev.pipeline.driver import InputTopics, PipelineDriver
from teleprev.pipeline.older_formats.step_commands import StepCommandsPipeline, StepCommandsResult, StepCommandsState
from teleprev.pipeline.step import HandInput


class StepCommandsDriver(PipelineDriver):
    recorded_topics = PipelineDriver.recorded_topics + (topics.COMMAND_ARM, topics.COMMAND_HAND)

    def __init__(self, pipeline: StepCommandsPipeline, inputs: InputTopics):
        super().__init__(pipeline, inputs)
        self.state = StepCommandsState()

    def recorded_values(self, result: StepCommandsResult) -> tuple[np.ndarray | None, ...]:
        return super().recorded_values(result) + (result.arm_command, result.effector_command)

    def _recorded_names(self) -> tuple[tuple[str, ...], ...]:
        return super()._recorded_names() + (self.pipeline.arm_names, self.pipeline.effector_names)

    def request_mode(self, mode: str, t_ns: int) -> str:
        self.state, refused = self.pipeline.set_mode(self.state, mode, self._inputs(t_ns))
        return refused

    def _step(self, topic: str, t_ns: int, hand_input: HandInput | None) -> StepCommandsResult | None:
        if not self.topics.action and topic == self.topics.arm and self.pipeline.motion is not None:
            return self.pipeline.idle_step(self.state, self._inputs(t_ns))
        return super()._step(topic, t_ns, hand_input)
