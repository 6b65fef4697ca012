"""A recording on a bimanual rig: both sides' devices, a pipeline and a paced sender per side, one loop,
one file. `open_session` picks it for a rig with [sides] (teleprev/sides.py), LiveSession otherwise.

The file holds the devices' raw streams under their own names (/glove/glove_left/hand, /arm/arm_right/state),
and each side's pipeline results and commands on topics with the side after the first segment
(/pipeline/left/corrected, /command/right/arm, /command/right/tick: teleprev/pipeline/bimanual.py). The
"sides" metadata record names, per side, the devices and robot; an export reads it to name the dataset's
joints as LeRobot's bimanual robots do ("left_arm.joint1", ..., "right_hand.15").
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev import topics
from teleprev.bimanual import build_guard, build_side_pipelines, mount, side_inputs
from teleprev.clock import SessionClock
from teleprev.devices.contract import GESTURE
from teleprev.errors import ConfigError
from teleprev.live.core.bimanual_loop import BimanualLoop
from teleprev.live.core.loop import LoopInbox
from teleprev.live.record.frames import RobotFrames
from teleprev.live.record.metadata import session_metadata
from teleprev.live.record.operator_actions import ACTION_KEYS, operator_status
from teleprev.live.record.session import PREVIEW_SLACK_S, URDF_MEDIA_TYPE, LiveSession, RecordOptions, inside_limits
from teleprev.messages import Transform, TransformsSample
from teleprev.pipeline.bimanual import BimanualDriver, side_topic
from teleprev.rig import Rig, load_rig
from teleprev.robot.frames import FramePublisher
from teleprev.robot.model import load_robot
from teleprev.sides import SIDES
from teleprev.transforms import matrix_to_quat

SIDES_RECORD = "sides"  # metadata record: side -> JSON of its devices, robot and end effector
GESTURE_REFUSED = ("both hands drive robots, so pinches do nothing: use the foot pedal (Page Down: preview/execute, "
                   "Page Up: next episode) or the page's buttons")


def open_session(options: RecordOptions) -> LiveSession:
    """The recording for the rig of `options`: bimanual for a rig with [sides], else single-arm."""
    rig = load_rig(options.rig)
    return BimanualSession(options) if rig.bimanual else LiveSession(options)


@dataclass
class _MetadataView:
    """What session_metadata reads of a session, for the right side (the left's models are recorded too)."""

    rig: Rig
    options: RecordOptions
    task: str
    pipeline: object
    driver: object
    preview_lead_s: float
    physics: object = None


def sides_record(rig: Rig) -> dict[str, str]:
    return {side: json.dumps({**s.devices, "robot": s.robot, "end_effector": s.section.end_effector,
                              "hand_urdf": s.effector.hand_urdf}) for side, s in rig.sides.items()}


class BimanualSession(LiveSession):
    def __init__(self, options: RecordOptions):  # noqa: PLR0915 (the wiring of one recording, in order)
        from teleprev.devices.runner import ActuatorPort, DeviceRunner
        from teleprev.live.core.actuator_host import ActuatorHost
        from teleprev.live.core.sender import CommandSender
        from teleprev.pipeline.planner import CommandPlanner
        from teleprev.session.recorder import LAG_BUDGET_S, Recorder

        self.options = options
        rig = load_rig(options.rig)
        if options.webxr_host:  # the XR page's devices of both sides: one page, one address
            rig = rig.with_device_settings("webxr", "--webxr-host", host=options.webxr_host)
        self.rig = rig
        if options.foxglove is not None:
            raise ConfigError("a bimanual rig records with its glove/suit (or XR page) devices only for now (no "
                              "--foxglove yet)", str(rig.path))
        if rig.sim.world == "physics":
            raise ConfigError("a bimanual rig has no physics world yet: use [sim] world = \"kinematic\"",
                              f"{rig.path} [sim]")
        self.task = options.task or rig.rig.task
        out = Path(options.out)
        if out.exists():
            raise ConfigError("a session with this name exists already; choose another --out", str(out))
        self.clock = SessionClock()
        self.physics = None
        # Each side's devices see that side's robot; each side has its own kinematic sim world (shared dict).
        self.context = rig.device_context(self.clock)
        contexts = rig.side_contexts(self.context)
        self.contexts = [self.context, *contexts.values()]
        device_sides = rig.device_sides()
        self.devices = rig.open_devices(rig.devices, self.context, contexts)
        self.pipelines = build_side_pipelines(rig, options.models)
        policy = options.policy is not None  # a policy's actions step each side (/policy/<side>/action)
        self.driver = BimanualDriver({side: (_driver(self.pipelines[side], rig, side, policy), side_inputs(rig, side))
                                      for side in SIDES}, build_guard(rig, self.pipelines))
        self.pipeline = self.pipelines["right"]
        self.robots = {side: load_robot(s.robot) for side, s in rig.sides.items()}
        self.robot = self.robots["right"]
        out.parent.mkdir(parents=True, exist_ok=True)
        self.view = None
        meta = session_metadata(_MetadataView(rig, options, self.task, self.pipeline,
                                              self.driver.drivers["right"], self.preview_lead_s))
        meta[SIDES_RECORD] = sides_record(rig)
        meta["pipeline"] = {"inputs": json.dumps(side_inputs(rig, "right").topics.__dict__),
                            "sides": json.dumps({side: side_inputs(rig, side).topics.__dict__ for side in SIDES})}
        left_models = self.pipelines["left"].model_hashes()
        if left_models is not None:
            meta["models_left"] = left_models
        attachments = {r.urdf_path.name: (URDF_MEDIA_TYPE, Path(r.urdf_path).read_bytes())
                       for r in self.robots.values()}
        self.recorder = Recorder(out, meta, attachments=attachments, on_failure=self._recording_failed,
                                 lag_budget_s=LAG_BUDGET_S, on_behind=self._recording_behind)
        inbox = LoopInbox(options.queue_size)
        # An actuator whose plugin allows it runs in a paced process of its own (live/core/actuator_host.py), fed
        # by its side's sender: "<side>/<kind>" -> its host.
        self.hosts = {}
        for side, s in rig.sides.items():
            p = self.pipelines[side]
            names = {"arm": p.arm_names, "hand": p.effector_names}
            for kind in ("arm", "hand"):
                device = self.devices[s.devices[kind]]
                if device.own_process:
                    self.hosts[f"{side}/{kind}"] = ActuatorHost(kind, device, inbox.sink, self.clock, names[kind])
        hosted = {host.name: host for host in self.hosts.values()}
        self.runners = {name: hosted.get(name) or DeviceRunner(dev, inbox.sink, self.clock)
                        for name, dev in self.devices.items()}
        actuators = {side: {kind: self.hosts.get(f"{side}/{kind}") or
                            ActuatorPort(self.devices[s.devices[kind]], self.runners[s.devices[kind]])
                            for kind in ("arm", "hand")} for side, s in rig.sides.items()}
        self.senders = {side: CommandSender(CommandPlanner.for_pipeline(p), self.clock,
                                            rig.sides[side].pipeline.command_rate_hz,
                                            outlets=tuple(h.outlet for key, h in self.hosts.items()
                                                          if key.startswith(f"{side}/")),
                                            warm_pose=inside_limits(self.robots[side], p.arm_names,
                                                                     p.effector_names))
                        for side, p in self.pipelines.items()}
        self.sender = self.senders["right"]  # (the file's sender record: both sides run at the same rate)
        tf_period_ns = int(1e9 / rig.pipeline.tf_rate_hz) if rig.pipeline.tf_rate_hz > 0 else 0
        side_frames = {side: SideFrames(side, RobotFrames(FramePublisher(robot), tf_period_ns), mount(rig, side))
                       for side, robot in self.robots.items()}
        self.loop = BimanualLoop(self.clock, self._log, self.driver, inbox=inbox, actuators=actuators,
                                 senders=self.senders, device_sides=device_sides, side_frames=side_frames,
                                 input_loss_to_preview_s=rig.session.input_loss_to_preview_s,
                                 on_episode_start=self._episode_started,
                                 hosted={side: frozenset(k.split("/")[1] for k in self.hosts
                                                         if k.startswith(f"{side}/")) for side in SIDES})
        for key, host in self.hosts.items():
            host.on_wire = lambda record, side=key.split("/")[0]: self.loop.wired_side(side, record)
        self.summary = None
        self.cannot_start = False
        self._press = self._press_unattended
        self.context.operator.act = self.act
        self.context.operator.status = lambda: {**operator_status(self.loop.snapshot), "gestures": False}

    def act(self, action: str, via: str = "") -> str:
        """As LiveSession's, but a hand gesture is refused: both hands drive robots, so a pinch is a grasp, not a
        control (the XR page stops reading pinches when the status says gestures: false; this holds if it did
        not). The foot pedal (teleprev/preview/keys.py) and the page's buttons do what the pinches did."""
        if via == GESTURE and action in ACTION_KEYS:
            return GESTURE_REFUSED
        return super().act(action, via)

    @property
    def preview_lead_s(self) -> float:
        """LiveSession's, for the side that takes longer to brake."""
        bound = max(p.motion.stop_time_bound() for p in self.pipelines.values())
        rate = min(s.pipeline.command_rate_hz for s in self.rig.sides.values())
        return bound + 2.0 / rate + PREVIEW_SLACK_S

    def _episode_started(self, task: str) -> None:
        for context in self.contexts:
            for listener in context.task_listeners:
                listener(task)

    def start(self) -> BimanualSession:
        return self._start(self.senders.values(),
                           {side_topic(topics.ROBOT_DESCRIPTION, side): robot for side, robot in self.robots.items()})


WORLD_FRAME = "world"  # the root of a bimanual /tf tree: each side's robot hangs from it at its mount


@dataclass
class SideFrames:
    """One side's robot on /tf, its frames named "<side>/<link>" under WORLD_FRAME at the side's mount, so both
    robots share one tree (a Foxglove URDF layer per side, with the frame prefix "<side>/")."""

    side: str
    frames: RobotFrames
    mount: np.ndarray  # 4x4: the robot's root in the world

    def sample(self, driver, arm_state) -> TransformsSample | None:
        tf = self.frames.sample(driver, arm_state)
        if tf is None:
            return None
        root = self.frames.publisher.model.desc.root
        mounted = Transform(WORLD_FRAME, f"{self.side}/{root}", self.mount[:3, 3].copy(),
                            matrix_to_quat(self.mount[:3, :3]))
        return TransformsSample(tf.stamp_ns, (mounted, *(
            Transform(f"{self.side}/{t.parent}", f"{self.side}/{t.child}", t.translation, t.rotation)
            for t in tf.transforms)))


def _driver(pipeline, rig: Rig, side: str, policy: bool = False):
    """A side's driver; `policy`: stepped by the policy's actions for this side (Pipeline.joint_step) instead
    of the glove."""
    from dataclasses import replace

    from teleprev.assembly import build_driver

    inputs = side_inputs(rig, side).topics
    if policy:
        inputs = replace(inputs, action=side_topic(topics.POLICY_ACTION, side))
    return build_driver(pipeline, inputs)

