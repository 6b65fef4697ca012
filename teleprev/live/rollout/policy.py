"""A trained policy in the session loop (`teleprev rollout`): its observations and its actions.

    PolicyFeatures   what the policy observes and does, as the export recipe defines a dataset's features
                     (datasets/recipes/default.toml): `observation.state` from the measured arm and end
                     effector, `observation.images.<camera>` from each camera, `action` the arm and end
                     effector's joints (the pipeline's `action_names`); `observation.images.<camera>_depth`
                     from a depth camera, for a policy trained with it: (H, W, 1) float32 in the unit the
                     training's LeRobotDataset gave (lerobot-train's depth_output_unit, millimetres by
                     default), which lerobot's prepare_observation_for_inference makes (1, 1, H, W) as
                     the dataset's batches are
    LatestSamples    the session loop's tap: the latest logged sample of each stream
    PolicyRunner     two threads. Inference: whenever no more actions are left than the last inference
                     took frames (LEAD at least), the latest observation goes through the policy, and its
                     plan (an ACT chunk: n_action_steps actions, one per frame) replaces what was left,
                     less the frames its inference took (its last action is kept: a policy slower than
                     its chunk still moves the robot, at its inference rate). A policy that keeps its own
                     sequence (lerobot's select_action: Diffusion, pi0, ...) has its actions queued in turn.
                     Pacing: once per frame at the dataset's fps, the next action is handed on (to the
                     session loop, as a sample on /policy/action), or none if the queue ran dry.

The actions are the operator's targets from then on (Pipeline.joint_step: the arm clipped into its limits,
the hand through the Corrector, then the same gate and paced sender); the sender's commands leave at its
own rate whatever the policy does, and when actions stop coming their targets go stale and the robot
brakes to rest within its limits, as for a silent glove.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Protocol

import numpy as np

from teleprev import topics
from teleprev.errors import ConfigError
from teleprev.export.recipe import DEPTH_SCHEMAS, IMAGE, JOINTS, POSE, Recipe, ResolvedFeature, resolve
from teleprev.export.streams import pose_values
from teleprev.messages import DepthSample, ImageSample, JointSample, Logged, PoseSample

# a StreamSpec's payload -> its recorded schema (depth: the RawImage it is recorded as by default)
SCHEMAS = {"joints": JOINTS, "pose": POSE, "image": IMAGE, "depth": DEPTH_SCHEMAS[0]}
LEAD = 2  # actions left, at least, when the next inference starts (frames of slack for its latency)


class Policy(Protocol):
    # True: each call plans from this observation on (ACT's chunk), superseding what is queued; False: each
    # call gives the next action(s) of the policy's own sequence (its select_action), queued after the rest
    plans_ahead: bool

    def chunk(self, observation: dict[str, np.ndarray], task: str) -> np.ndarray: ...

    def reset(self) -> None: ...


@dataclass(frozen=True)
class PolicyFeatures:
    observations: tuple[ResolvedFeature, ...]  # state vectors, images and depth maps, in the recipe's order
    action: ResolvedFeature
    depth_per_m: float = 1000.0  # a depth map's units per metre, as the policy was trained (millimetres: 1000)

    @classmethod
    def for_streams(cls, recipe: Recipe, streams: dict[str, str], inputs: dict[str, str],
                    sides: dict[str, str] | None = None) -> PolicyFeatures:
        """The recipe's features over a live session's streams (topic -> StreamSpec payload) and the
        pipeline's inputs (InputTopics' fields, which pick the device where a rig has several); `sides`: a
        bimanual session's "sides" record (each role once per side, left first, as its export makes them)."""
        from teleprev.pipeline.bimanual import side_topic
        from teleprev.sides import SIDES

        schemas = {t: SimpleNamespace(schema=SCHEMAS.get(p, p)) for t, p in streams.items()}
        commands = [topics.COMMAND_ARM, topics.COMMAND_HAND]  # a dataset's action: the commands
        if sides:
            commands = [side_topic(t, side) for side in SIDES for t in commands]
        for t in commands:
            schemas[t] = SimpleNamespace(schema=JOINTS)
        metadata = {"pipeline": {"inputs": json.dumps(inputs)}, **({"sides": sides} if sides else {})}
        features = resolve(recipe, schemas, metadata, "rollout")
        actions = [f for f in features if f.is_action]
        if len(actions) != 1 or [s.topic for s in actions[0].sources] != commands:
            raise ConfigError("a policy's action must be the recipe's one action feature made of "
                              "arm_command and effector_command (the joints the pipeline commands)", recipe.path)
        return cls(tuple(f for f in features if not f.is_action), actions[0])

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(f.name for f in self.observations)

    def observed_by(self, inputs, depth_per_m: float) -> PolicyFeatures:
        """Only the features a policy takes (`inputs`: its input feature names): one trained without depth gets
        none, nor anything else the recipe makes that it was not trained on."""
        return PolicyFeatures(tuple(f for f in self.observations if f.name in inputs), self.action, depth_per_m)


class LatestSamples:
    """The latest logged sample of each stream: a SessionLoop tap (called on the loop's thread)."""

    def __init__(self) -> None:
        self._latest: dict[str, object] = {}

    def __call__(self, msg: Logged) -> None:
        self._latest[msg.topic] = msg.payload  # one dict store: atomic under the interpreter lock

    def get(self, topic: str):
        return self._latest.get(topic)


def observe(features: PolicyFeatures, latest: LatestSamples) -> dict[str, np.ndarray] | None:
    """One observation as a dataset's frame holds it (float32 vectors, RGB uint8 height x width x 3, depth
    float32 height x width x 1 in the policy's depth unit), from the latest samples; None until every stream
    has sent something."""
    out: dict[str, np.ndarray] = {}
    for f in features.observations:
        samples = [latest.get(s.topic) for s in f.sources]
        if any(s is None for s in samples):
            return None
        if f.is_image:
            out[f.name] = decode_jpeg(samples[0])
            continue
        if f.is_depth:
            out[f.name] = depth_map(samples[0], features.depth_per_m)
            continue
        parts = []
        for s in samples:
            if isinstance(s, PoseSample):
                parts.append(pose_values(s))
            elif isinstance(s, JointSample):
                parts.append(np.asarray(s.positions, dtype=float))
        out[f.name] = np.concatenate(parts).astype(np.float32)
    return out


def decode_jpeg(sample: ImageSample) -> np.ndarray:
    from teleprev.export.session import rgb_image

    image = rgb_image(sample.data)
    if image is None:
        raise ValueError(f"a camera image stamped {sample.stamp_ns} does not decode")
    return image


def depth_map(sample: DepthSample, per_m: float) -> np.ndarray:
    """A depth frame as the policy's dataset gave it: (H, W, 1) float32 in metres times `per_m`."""
    from teleprev.export.session import depth_image

    image = depth_image(sample)
    return image if per_m == 1.0 else image * np.float32(per_m)


@dataclass
class RunnerStats:
    inferences: int = 0
    inference_s: list[float] = field(default_factory=list)
    handed: int = 0  # actions handed on
    starved: int = 0  # frames with no action to hand on
    dropped: int = 0  # planned actions whose frame had passed before the plan arrived
    failure: str = ""  # why inference stopped (the policy raised), or ""

    def policy_hz(self) -> float:
        """Inferences a second while inferring: 1 / mean inference time."""
        return len(self.inference_s) / sum(self.inference_s) if self.inference_s and sum(self.inference_s) > 0 else 0.0


class PolicyRunner:
    """Inference on one thread, one action per frame handed on from another (see the module's doc).
    `deliver(action)` gets each action (float64, the action feature's width); `observe()` gives the
    latest observation or None; `on_failure(why)` is told once if the policy raises."""

    def __init__(self, policy: Policy, observe: Callable[[], dict | None], deliver: Callable[[np.ndarray], None],
                 fps: float, on_failure: Callable[[str], None] = lambda why: None, lead: int = LEAD,
                 on_acting: Callable[[], None] = lambda: None):
        self.policy = policy
        self.observe = observe
        self.deliver = deliver
        self.period_s = 1.0 / fps
        self.on_failure = on_failure
        self.on_acting = on_acting  # told after an episode's first action was handed on
        self.lead = lead
        self.stats = RunnerStats()
        self.task = ""
        self._queue: deque[np.ndarray] = deque()
        self._lock = threading.Condition()
        self._stop = threading.Event()
        self._reset = False
        self._acted = True  # an action was handed on since the episode started
        self._threads: list[threading.Thread] = []

    def start(self) -> PolicyRunner:
        self._threads = [threading.Thread(target=self._infer, name="policy-inference", daemon=True),
                         threading.Thread(target=self._pace, name="policy-pacing", daemon=True)]
        for t in self._threads:
            t.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """No action is handed on from now; an inference still running after `timeout` (a stalled policy)
        is left to end on its own (daemon) thread, so a session never waits on it to close its file."""
        self._stop.set()
        with self._lock:
            self._lock.notify_all()
        for t in self._threads:
            t.join(timeout)

    def new_episode(self, task: str) -> None:
        """An episode starts: forget the plan, and the policy its history, before the next inference."""
        with self._lock:
            self.task = task
            self._queue.clear()
            self._reset = True
            self._acted = False
            self._lock.notify_all()

    def queued(self) -> int:
        with self._lock:
            return len(self._queue)

    # ---- threads -------------------------------------------------------------------------------
    def _infer(self) -> None:
        while not self._stop.is_set():
            with self._lock:
                while len(self._queue) > self._lead() and not self._stop.is_set():
                    self._lock.wait(self.period_s)
                reset, self._reset, task = self._reset, False, self.task
            if self._stop.is_set():
                return
            try:
                if reset:
                    self.policy.reset()
                observation = self.observe()
                if observation is None:  # a stream has not sent yet
                    self._stop.wait(self.period_s)
                    continue
                started = time.monotonic()
                plan = np.asarray(self.policy.chunk(observation, task), dtype=float)
                took = time.monotonic() - started
            except Exception as exc:  # the robot brakes (no more actions); the session says why
                self.stats.failure = f"the policy failed: {type(exc).__name__}: {exc}"
                self.on_failure(self.stats.failure)
                return
            late = int(took / self.period_s)  # the plan's first actions were for frames that have passed
            with self._lock:
                self.stats.inferences += 1
                self.stats.inference_s.append(took)
                if self._reset:  # an episode started meanwhile: this plan was for the last one
                    continue
                if getattr(self.policy, "plans_ahead", True):
                    late = min(late, len(plan) - 1)
                    self.stats.dropped += late
                    self._queue = deque(plan[late:])
                else:
                    self._queue.extend(plan)

    def _lead(self) -> int:
        """Actions left when the next inference starts: as many frames as the last one took, and one."""
        took = self.stats.inference_s[-1] if self.stats.inference_s else 0.0
        return max(self.lead, math.ceil(took / self.period_s) + 1)

    def _pace(self) -> None:
        due = time.monotonic()
        while not self._stop.is_set():
            due += self.period_s
            wait = due - time.monotonic()
            if wait < -self.period_s:  # woke a frame late or more: keep the pace from now, no burst
                due = time.monotonic()
            elif wait > 0 and self._stop.wait(wait):
                return
            with self._lock:
                action = self._queue.popleft() if self._queue else None
                first = action is not None and not self._acted
                self._acted = self._acted or first
                self._lock.notify_all()
            if action is None:
                self.stats.starved += 1
                continue
            self.stats.handed += 1
            self.deliver(action)
            if first:
                self.on_acting()
