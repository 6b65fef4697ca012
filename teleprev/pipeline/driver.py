"""Feeds a Pipeline from one ordered stream of logged samples, live or from a recording.

It keeps the latest sample of each input stream, runs a step on every sample of the trigger stream (the
glove: pipeline outputs at glove rate; with an `action` topic, a policy's actions: `Pipeline.joint_step`
on each, the glove and suit only recorded) and applies mode switches. A trigger sample that a
/events/superseded record names (the live loop, behind, stepped a newer one instead) only updates the
latest sample. Everything it decides depends only on the samples and their log times, in log-time order.
Each step's targets and each accepted mode switch become an update for the command planner
(`take_updates`), so replaying a session's raw streams and its mode switches through a driver built from
the same rig and models, and the updates through a planner at the recorded ticks, reproduces the
recorded commands.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from teleprev import topics
from teleprev.messages import Event, JointSample, Logged, PoseSample
from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.planner import ModeUpdate, TargetUpdate
from teleprev.pipeline.step import HandInput, Pipeline, PipelineState, StepInputs, StepResult


@dataclass(frozen=True)
class InputTopics:
    hand: str  # glove hand pose: also the trigger (unless `action` is set)
    wrist: str
    arm: str
    effector: str
    action: str = ""  # joint targets asked for directly (a policy's, topics.POLICY_ACTION): the trigger instead

    @classmethod
    def for_devices(cls, glove: str, suit: str, arm: str, hand: str) -> InputTopics:
        return cls(
            topics.device_topic("glove", glove, "hand"),
            topics.device_topic("suit", suit, "wrist"),
            topics.device_topic("arm", arm, "state"),
            topics.device_topic("hand", hand, "state"),
        )


@dataclass
class Outputs:
    """What one fed sample produced: the messages to record (the commands are the sender's)."""

    logged: list[tuple[str, object]] = field(default_factory=list)  # (topic, payload) stamped at the trigger time
    result: StepResult | None = None


class PipelineDriver:
    # The JointStates streams a step's results are recorded on, in the order they are recorded.
    recorded_topics: tuple[str, ...] = (topics.RETARGETED, topics.CORRECTED, topics.ARM_TARGET)

    def __init__(self, pipeline: Pipeline, inputs: InputTopics):
        self.pipeline = pipeline
        self.topics = inputs
        self._input_topics = frozenset(
            t for t in (inputs.hand, inputs.wrist, inputs.arm, inputs.effector, inputs.action) if t
        )
        self.state = PipelineState()
        self.latest: dict[str, object] = {}
        self.last_result: StepResult | None = None
        self.recorded_names = self._recorded_names()
        self._seq = 0  # the planner's updates, numbered in the order they are made
        self._updates: list[TargetUpdate | ModeUpdate] = []
        self._superseded: set[int] = set()  # log times of samples recorded but not to be stepped

    def recorded_values(self, result: StepResult) -> tuple[np.ndarray | None, ...]:
        """What one step records on each of `recorded_topics`, in that order (None: nothing): the one place
        that says which result goes on which topic, for the live recorder (`feed`) and the evaluation's
        re-run alike. The corrected hand is recorded only with a retargeted one. (A tuple, not a dict: the
        evaluation calls it on every step.)"""
        retargeted = result.retargeted
        return retargeted, None if retargeted is None else result.corrected, result.arm_target

    def _recorded_names(self) -> tuple[tuple[str, ...], ...]:
        """The joint names of each of `recorded_topics`, in that order."""
        arm, eff = self.pipeline.arm_names, self.pipeline.effector_names
        return eff, eff, arm

    def take_updates(self) -> list[TargetUpdate | ModeUpdate]:
        """The planner's updates made since the last call, in order."""
        out, self._updates = self._updates, []
        return out

    def _queue(self, update) -> None:
        self._seq += 1
        self._updates.append(evolve(update, seq=self._seq))

    @property
    def mode(self) -> str:
        return self.state.mode

    def _inputs(self, t_ns: int, hand_input: HandInput | None = None) -> StepInputs:
        g = self.latest.get
        return StepInputs(t_ns, g(self.topics.hand), g(self.topics.wrist), g(self.topics.arm), g(self.topics.effector),
                          hand_input, g(self.topics.action) if self.topics.action else None)

    def prepare(self, messages: list[Logged]) -> list[HandInput | None]:
        """For a run of messages about to be fed: Pipeline.prepare_hands of each trigger sample, in one
        batch (None for the other messages), to pass to `feed` with its message."""
        if self.topics.action:  # the glove steps nothing
            return [None] * len(messages)
        hand = [i for i, m in enumerate(messages) if m.topic == self.topics.hand and isinstance(m.payload, JointSample)]
        out: list[HandInput | None] = [None] * len(messages)
        for i, prepared in zip(hand, self.pipeline.prepare_hands([messages[i].payload for i in hand])):
            out[i] = prepared
        return out

    def request_mode(self, mode: str, t_ns: int) -> str:
        """Switch preview/execute (or "estop") at log time t_ns; returns "" or why it was refused. An accepted
        switch makes the planner's ModeUpdate; asking for the mode it is in already changes nothing (an
        e-stop excepted)."""
        inputs = self._inputs(t_ns)
        before = self.state.mode
        self.state, refused = self.pipeline.set_mode(self.state, mode, inputs)
        if not refused and (mode == "estop" or self.state.mode != before):
            self._queue(self.pipeline.mode_update(mode, inputs, 0))
        return refused

    def feed(self, msg: Logged, hand_input: HandInput | None = None) -> Outputs:
        """One logged sample, in log-time order; `hand_input`: its entry from `prepare`, if any."""
        result = self.advance(msg, hand_input)
        return Outputs() if result is None else self._outputs(result, msg.log_time_ns)

    def advance(self, msg: Logged, hand_input: HandInput | None = None) -> StepResult | None:
        """What `feed` does, without making the messages to record: the step's result, or None when the
        sample stepped nothing (an input sample other than the trigger's or superseded, a mode switch)."""
        payload = msg.payload
        topic = msg.topic
        if topic in self._input_topics:
            if isinstance(payload, (JointSample, PoseSample)):
                self.latest[topic] = payload
            if msg.log_time_ns in self._superseded:  # a newer sample was queued already: it steps instead
                self._superseded.discard(msg.log_time_ns)
                return None
        elif topic == topics.SUPERSEDED and isinstance(payload, Event):
            self._superseded.add(int(payload.data["log_time_ns"]))
            return None
        elif topic == topics.MODE and isinstance(payload, Event):
            # A recorded switch: it was accepted live, and the same state accepts it again.
            data = payload.data
            mode = "estop" if data.get("reason") == "estop" or data.get("halt") else data.get("mode", "")
            self.request_mode(mode, msg.log_time_ns)
            return None
        result = self._step(topic, msg.log_time_ns, hand_input)
        if result is not None:
            self.state = result.state
            self.last_result = result
            if result.update is not None:
                self._queue(result.update)
        return result

    def _step(self, topic: str, t_ns: int, hand_input: HandInput | None) -> StepResult | None:
        """The step a sample of `topic` triggers (the glove's, or with an `action` topic the policy's), or
        None."""
        if self.topics.action:
            return self.pipeline.joint_step(self.state, self._inputs(t_ns)) if topic == self.topics.action else None
        if topic == self.topics.hand:
            return self.pipeline.step(self.state, self._inputs(t_ns, hand_input))
        return None

    def _outputs(self, result: StepResult, t: int) -> Outputs:
        out = Outputs(result=result)
        for topic, names, value in zip(self.recorded_topics, self.recorded_names, self.recorded_values(result)):
            if value is not None:
                out.logged.append((topic, JointSample(t, names, value)))
        out.logged.append((topics.STEP_REPORT, Event(t, "teleprev.StepReport", _json_ready(result.report))))
        return out


def _json_ready(report: dict) -> dict:
    return {
        k: (float(v) if isinstance(v, np.floating) else bool(v) if isinstance(v, np.bool_) else v)
        for k, v in report.items()
    }
