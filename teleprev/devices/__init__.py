"""The device plugin API: everything a plugin needs from teleprev, importable from this one module.

    from teleprev.devices import Device, DeviceContext, StreamSpec, JointSample, DeviceError

A plugin (devices/teleprev_devices, or a third party's) imports nothing else of teleprev. See
docs/writing-a-plugin.md for a complete plugin, its entry point and its test.

The robot model, its geometry and the session reader are imported on first use, so that
`import teleprev.devices` stays light.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from teleprev import transforms
from teleprev.clock import ClockSync, SessionClock
from teleprev.devices.contract import (
    GESTURE,
    KINDS,
    Actuator,
    Device,
    DeviceContext,
    NoSettings,
    OperatorLink,
    StreamSpec,
)
from teleprev.devices.pacing import wait_until_due
from teleprev.devices.physics import WORLDS, LayoutRecord, PhysicsAccess
from teleprev.devices.polled import DeviceFault, JointLimits, PolledActuator, PolledSettings
from teleprev.devices.registry import GROUP, available, load_plugin
from teleprev.devices.runner import ActuatorPort, DeviceRunner, RunnerStats, Sink, default_gap_s
from teleprev.devices.servo_limits import FAULT_TOLERANCE, ServoStreamRule, ServoViolation
from teleprev.errors import ConfigError, DeviceError, DeviceStartError, SessionError, TeleprevError, describe_exception
from teleprev.human import mirror as body_mirror
from teleprev.human import smplx
from teleprev.messages import (
    CameraInfo,
    DepthSample,
    Event,
    ImageSample,
    JointSample,
    Logged,
    PoseSample,
    Sample,
    Transform,
    TransformsSample,
)
from teleprev.robot.effectors import EFFECTORS, EndEffector, end_effector
from teleprev.thread_priority import INPUT_PRIORITY, PacedStatus, become_paced, raise_this_thread
from teleprev.topics import KIND_TOPICS, device_topic, parse_device_topic
from teleprev.world import places as world_places

if TYPE_CHECKING:
    from teleprev.robot import geometry as robot_geometry
    from teleprev.robot.model import RobotModel, load_robot
    from teleprev.session.reader import SessionReader

# name -> (module, attribute; "" for the module itself)
_LAZY = {
    "RobotModel": ("teleprev.robot.model", "RobotModel"),
    "load_robot": ("teleprev.robot.model", "load_robot"),
    "robot_geometry": ("teleprev.robot.geometry", ""),  # link shapes, for drawing the robot
    "SessionReader": ("teleprev.session.reader", "SessionReader"),
}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    module, attribute = _LAZY[name]
    value = importlib.import_module(module)
    if attribute:
        value = getattr(value, attribute)
    globals()[name] = value
    return value


__all__ = [
    # the contract
    "KINDS",
    "Actuator",
    "Device",
    "DeviceContext",
    "NoSettings",
    "OperatorLink",
    "GESTURE",
    "StreamSpec",
    "wait_until_due",
    "body_mirror",
    "DeviceFault",
    "JointLimits",
    "PolledActuator",
    "PolledSettings",
    "FAULT_TOLERANCE",
    "ServoStreamRule",
    "ServoViolation",
    # running and finding plugins
    "ActuatorPort",
    "DeviceRunner",
    "RunnerStats",
    "Sink",
    "default_gap_s",
    "GROUP",
    "available",
    "load_plugin",
    "raise_this_thread",  # a plugin's own receiving thread, at the session loop's priority
    "become_paced",  # a plugin's own decoding process, at real-time priority where permitted
    "PacedStatus",
    "INPUT_PRIORITY",
    # samples, time and topics
    "Event",
    "ImageSample",
    "JointSample",
    "Logged",
    "PoseSample",
    "Sample",
    "DepthSample",
    "CameraInfo",
    "Transform",
    "TransformsSample",
    "ClockSync",
    "SessionClock",
    "KIND_TOPICS",
    "device_topic",
    "parse_device_topic",
    # errors
    "ConfigError",
    "DeviceError",
    "DeviceStartError",
    "SessionError",
    "TeleprevError",
    "describe_exception",
    # what built-in plugins use: SMPL-X names, rotations, the robot, the end-effector table, recorded sessions
    "smplx",
    "transforms",
    "EFFECTORS",
    "EndEffector",
    "end_effector",
    "world_places",
    # the physics world of a [sim] world = "physics" rig (DeviceContext.physics)
    "WORLDS",
    "LayoutRecord",
    "PhysicsAccess",
    "RobotModel",
    "load_robot",
    "robot_geometry",
    "SessionReader",
]
