"""A policy rollout: a live session whose pipeline is driven by a trained policy instead of the operator.

    check_rollout(options)   what can be refused before anything opens: the policy folder, its features
                             against the rig's streams and the export recipe, the episode times
    Rollout(options, policy) the session (LiveSession, recorded like `record`'s) with the policy's
                             observations tapped from the session loop and its actions handed back to it
                             on /policy/action (teleprev/live/rollout/policy.py), episodes timed by `run_timed`

Every episode starts in preview (the robot gets no motion command while the policy's targets show) and
engages `engage_after_s` into it through the normal engage path; the episode ends back in preview, the
commands braking to rest. The session records the policy's raw actions, so `teleprev eval` re-runs the
pipeline from them bit for bit, `teleprev audit` measures its commands and `teleprev export` makes data of it.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.clock import SessionClock
from teleprev.errors import ConfigError
from teleprev.export.recipe import Recipe, load_recipe
from teleprev.live.no_signals import NoSignals
from teleprev.live.record.bimanual_session import open_session, sides_record
from teleprev.live.record.run import run_timed
from teleprev.live.record.schedule import EpisodeTimes
from teleprev.live.record.session import LiveSession, RecordOptions
from teleprev.live.rollout.lerobot_policy import DEPTH_UNITS_M, PolicyCard
from teleprev.live.rollout.policy import LatestSamples, PolicyFeatures, PolicyRunner, observe
from teleprev.messages import JointSample, Sample
from teleprev.pipeline.bimanual import side_topic
from teleprev.pipeline.step import action_names as joint_action_names
from teleprev.rig import Rig, load_rig, side_rig
from teleprev.robot.model import load_robot
from teleprev.sides import SIDES

DEFAULT_FPS = 30  # a recipe without fps and a rig without camera (as the export's)
WAITING = "the policy has not acted yet in this episode"  # why an episode's engage waits
POLICY = "policy"  # who holds execute back until then


@dataclass
class RolloutOptions:
    policy: Path
    out: Path
    rig: Path | None = None  # None: the default all-sim rig
    episodes: int = 1
    episode_time_s: float = 10.0
    engage_after_s: float = 1.0
    reset_time_s: float = 0.0  # between episodes, the robot in preview (someone resets the scene)
    recipe: str | None = None  # the export recipe the policy's dataset was made with (None: the default)
    models: Path | None = None
    task: str = ""
    connect_timeout_s: float = 5.0


@dataclass(frozen=True)
class RolloutPlan:
    """What check_rollout found: the policy, its features over the rig, and the frame rate."""

    card: PolicyCard
    recipe: Recipe
    rig: Rig
    features: PolicyFeatures
    action_names: tuple[str, ...]
    fps: float


def _rig_streams(rig: Rig) -> tuple[dict[str, str], dict[str, float], dict[str, str]]:
    """(topic -> payload, topic -> rate, the pipeline's input topics) of a rig's devices, without opening them."""
    from teleprev.pipeline.driver import InputTopics

    context = rig.device_context(SessionClock())
    streams, rates = {}, {}
    for name, entry in rig.devices.items():
        for spec in entry.cls(name, entry.settings, context).streams():
            streams[spec.topic], rates[spec.topic] = spec.payload, spec.rate_hz
    first = {kind: rig.of_kind(kind)[0].name for kind in ("glove", "suit", "arm", "hand")}
    inputs = InputTopics.for_devices(first["glove"], first["suit"], first["arm"], first["hand"])
    return streams, rates, dict(inputs.__dict__)


def _joint_names(rig: Rig) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The arm's joints (the chain the wrist drives) and the end effector's, as the pipeline names them."""
    robot = load_robot(rig.rig.robot)
    tip = rig.pipeline.tcp_link or rig.effector.tcp_link
    effector = rig.effector.joints
    return tuple(n for n in robot.chain_to(tip).joint_names if n not in effector), tuple(effector)


def _joints(rig: Rig, inputs: dict[str, str]) -> tuple[tuple[str, ...], dict[str, int]]:
    """The action's joint names, as the export names them ("arm.joint1" ...; a bimanual rig's each side's
    "left_arm.joint1" ..., left first), and how many values each arm's and end effector's state stream has."""
    if not rig.bimanual:
        arm, effector = _joint_names(rig)
        return joint_action_names(arm, effector), {
            topics.device_topic("arm", inputs["arm"].split("/")[2], "state"): len(arm),
            topics.device_topic("hand", inputs["effector"].split("/")[2], "state"): len(effector)}
    names, widths = (), {}
    for side in SIDES:
        arm, effector = _joint_names(side_rig(rig, side))
        names += tuple(rig.sides[side].prefixed(n) for n in joint_action_names(arm, effector))
        devices = rig.sides[side].devices
        widths[topics.device_topic("arm", devices["arm"], "state")] = len(arm)
        widths[topics.device_topic("hand", devices["hand"], "state")] = len(effector)
    return names, widths


def check_rollout(options: RolloutOptions) -> RolloutPlan:
    """Refuses, with one ConfigError naming what is wrong, what would make the rollout fail later."""
    episode_plan(options).check()
    if Path(options.out).exists():
        raise ConfigError("a session with this name exists already; choose another --out", str(options.out))
    rig = load_rig(options.rig)
    rig.require("glove", "suit", "arm", "hand")
    if options.task:
        rig.check_task(options.task, "--task")
    recipe = load_recipe(options.recipe)
    card = PolicyCard.read(options.policy)  # after the options' own values: a wrong one is named, not the policy
    streams, rates, inputs = _rig_streams(rig)
    features = PolicyFeatures.for_streams(recipe, streams, inputs, sides_record(rig) if rig.bimanual else None)
    action_names, widths = _joints(rig, inputs)
    where = f"{card.path} config.json"
    given = {}
    for f in features.observations:
        if f.is_video:
            settings = rig.devices[f.sources[0].topic.split("/")[2]].settings
            h, w = getattr(settings, "height", None), getattr(settings, "width", None)
            given[f.name] = (1 if f.is_depth else 3, h, w) if h and w else None
        else:
            sizes = [widths.get(s.topic, 7 if s.schema.endswith("PoseInFrame") else None) for s in f.sources]
            given[f.name] = None if None in sizes else (sum(sizes),)
    missing = sorted(set(card.inputs) - set(given))
    if missing:
        raise ConfigError(
            f"the policy observes {', '.join(missing)}, which recipe {recipe.path} does not make from this "
            f"rig's streams (it makes {', '.join(given) or 'nothing'})",
            where,
        )
    for name, shape in card.inputs.items():
        if given[name] is not None and tuple(given[name]) != tuple(shape):
            raise ConfigError(f"the policy's {name} has shape {list(shape)}, this rig gives {list(given[name])}", where)
    action = card.outputs.get(features.action.name)
    if action is None or tuple(action) != (len(action_names),):
        raise ConfigError(f"the policy's {features.action.name} is {list(action) if action else 'missing'}; this rig's "
                          f"is {len(action_names)} joints ({', '.join(action_names)})", where)
    fps = float(card.dataset_fps or recipe.export.fps)
    if not fps:
        cameras = [f.sources[0].topic for f in features.observations if f.is_image]
        fps = round(rates[cameras[0]]) if cameras else DEFAULT_FPS
    observed = features.observed_by(card.inputs, DEPTH_UNITS_M[card.depth_unit])
    return RolloutPlan(card, recipe, rig, observed, action_names, fps)


def episode_plan(options: RolloutOptions) -> EpisodeTimes:
    """The rollout's timed episodes (teleprev/live/record/schedule.py), as `record --episode-time` runs them: each
    starts in preview, engages engage_after_s into it, and is back in preview, at rest, by its end."""
    return EpisodeTimes(options.episodes, options.episode_time_s, options.reset_time_s, options.engage_after_s)


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def session_action_names(recording: LiveSession) -> tuple[str, ...]:
    """The joints a session's pipeline (a bimanual one's two, prefixed, left first) takes as a policy's action."""
    pipelines = getattr(recording, "pipelines", None)
    if pipelines is None:
        return recording.pipeline.action_names
    return tuple(recording.rig.sides[side].prefixed(n) for side in SIDES for n in pipelines[side].action_names)


@dataclass
class RolloutResult:
    recording: LiveSession
    runner: PolicyRunner
    unconnected: list[str] = field(default_factory=list)


class Rollout:
    """The session and the policy's runner, wired (see the module's doc)."""

    def __init__(self, options: RolloutOptions, plan: RolloutPlan, policy):
        self.options, self.plan = options, plan
        card = plan.card
        record = {"path": str(card.path), "type": card.type, "model_sha256": _sha256(card.path / "model.safetensors"),
                  "fps": f"{plan.fps:g}", "recipe": plan.recipe.path, "action_names": ",".join(plan.action_names)}
        self.recording = open_session(RecordOptions(
            out=options.out, rig=options.rig, models=options.models, task=options.task,
            connect_timeout_s=options.connect_timeout_s, policy=record, episode_plan=episode_plan(options)))
        if session_action_names(self.recording) != plan.action_names:  # check_rollout names them as the pipeline
            self.recording.stop()
            raise ConfigError(f"the pipeline's joints {list(session_action_names(self.recording))} differ from the "
                              f"rollout's {list(plan.action_names)}", str(options.rig or "rig"))
        self.latest = LatestSamples()
        self.recording.loop.taps.append(self.latest)
        loop = self.recording.loop
        self.runner = PolicyRunner(policy, lambda: observe(plan.features, self.latest), self._deliver, plan.fps,
                                   on_failure=loop.halt, on_acting=lambda: loop.release(POLICY))
        self.recording.context.task_listeners.append(self._new_episode)

    def _new_episode(self, task: str) -> None:
        """An episode starts: it executes only once the policy's own targets for it have been previewed (the
        targets of the episode before would otherwise pass for them), so execute waits for its first action."""
        self.recording.loop.hold(POLICY, WAITING)
        self.runner.new_episode(self.recording.rig.task_text(task))

    def _deliver(self, action) -> None:
        clock = self.recording.clock
        now = clock.now_ns()
        pipelines = getattr(self.recording, "pipelines", None)
        if pipelines is None:
            self.recording.loop.sink(Sample(topics.POLICY_ACTION, JointSample(now, self.plan.action_names, action)),
                                     now)
            return
        start = 0  # a bimanual policy's action: left_* then right_*, each side's on /policy/<side>/action
        for side in SIDES:
            names = pipelines[side].action_names
            part = np.asarray(action[start:start + len(names)])
            start += len(names)
            self.recording.loop.sink(Sample(side_topic(topics.POLICY_ACTION, side), JointSample(now, names, part)), now)

    def run(self, signals=None) -> RolloutResult:
        """Start, run the episodes, stop (the file is closed even when interrupted). `signals`
        (teleprev.cli.signals.StopSignals): one whose interrupt start-up lost still stops the rollout before
        the policy acts, and none cuts the robot's stop and the file's close short."""
        signals = signals or NoSignals()
        o = self.options
        result = RolloutResult(self.recording, self.runner)
        try:
            with signals.deferred():
                self.recording.start()
            signals.check()
            result.unconnected = self.recording.wait_connected()
            signals.check()
            if not result.unconnected:
                self.runner.start()
                run_timed(self.recording, episode_plan(o))
        finally:
            with signals.finishing():
                self.runner.stop()
                self.recording.stop()
        return result
