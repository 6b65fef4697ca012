"""What a device plugin is, and how the session loop talks to it.

A plugin is a class registered under the `teleprev.devices` entry-point group (pyproject.toml), named
"<family>.<kind>", e.g. "sim.glove", "vmc.suit", "opencv.camera", "xarm.arm", "leap.hand". A rig file
picks one per device:

    [devices.glove]
    plugin = "sim.glove"
    rate_hz = 120          # the remaining keys are the plugin's Settings dataclass

The session loop gives every device its own reader thread that calls `read()` in a loop and hands the
samples on; actuators (arm, hand) also receive commands through `send()`. A device never blocks the
others: a fault is raised as DeviceError from `read()`/`connect()`, and the runner marks a gap and
tries to reconnect.
"""

from __future__ import annotations

import importlib
import importlib.util
import typing
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any, ClassVar, TypeVar

from teleprev.clock import SessionClock
from teleprev.devices.physics import PhysicsAccess
from teleprev.errors import DeviceError
from teleprev.messages import JointSample, Sample
from teleprev.robot.effectors import EndEffector, end_effector
from teleprev.topics import device_topic

KINDS = ("glove", "suit", "camera", "arm", "hand")


@dataclass(frozen=True)
class StreamSpec:
    """A stream a device produces: its topic, payload type ("joints", "pose", "image") and nominal rate."""

    topic: str
    payload: str
    rate_hz: float


GESTURE = "gesture"  # OperatorLink.act's `via` for an action asked by a hand gesture (the XR page's pinches)


@dataclass
class OperatorLink:
    """The recording behind a device that carries the operator's controls (an XR page): `act(action, via)` carries
    out an operator action (live.record.operator_actions names them) and says why not ("" when done, "unknown" for
    no such action); `via` is how the operator asked: "" (a button), or GESTURE (a hand's pinch, which a
    recording whose hands both drive robots refuses). `status()` is what the operator is shown. The recording
    sets both once it runs; outside one (devices check, calibrate) they stay None."""

    act: Callable[[str, str], str] | None = None
    status: Callable[[], dict] | None = None


@dataclass
class DeviceContext:
    """What a device gets from the rig besides its own settings."""

    clock: SessionClock
    rig_dir: Path = Path(".")
    shared: dict[str, Any] = field(default_factory=dict)  # state plugins of one family share (e.g. the sim world)
    robot: str = "xarm6_leap_hand"  # the rig's robot URDF name
    end_effector: str = "leap_hand"
    # Called with the task label whenever an episode starts (a simulated operator switches task on it).
    task_listeners: list[Callable[[str], None]] = field(default_factory=list)
    operator: OperatorLink = field(default_factory=OperatorLink)
    # The rig's physics world ([sim] world = "physics"), which sim devices measure from, command into and
    # render; None: the kinematic sim world.
    physics: PhysicsAccess | None = None
    # Sockets the rig's network plugins share (a VMC port, the XR page's server), whatever side their device is
    # on: a bimanual rig's sides each have their own `shared` (their own sim world) but one VMC sender.
    receivers: dict[Any, Any] = field(default_factory=dict)

    @property
    def effector(self) -> EndEffector:
        """The end effector's row of the one table (joints, TCP link, grasp point)."""
        return end_effector(self.end_effector)


@dataclass
class NoSettings:
    pass


S = TypeVar("S")


class Device[S](ABC):
    """A source of timestamped samples, configured by the dataclass S that the rig's [devices.<name>]
    table is read into. A plugin names its kind, and the optional SDK its hardware needs, as it subclasses:

        class MyGlove(Device[MyGloveSettings], kind="glove"): ...
        class MyArm(Actuator[MyArmSettings], kind="arm", sdk_module="myarm_sdk", extra="myarm"): ...
    """

    kind: ClassVar[str]  # one of KINDS
    Settings: ClassVar[type] = NoSettings  # S itself (a ClassVar cannot name a type variable)
    sdk_module: ClassVar[str] = ""  # the SDK's top-level module, e.g. "xarm"; "": no optional SDK
    extra: ClassVar[str] = ""  # the extra that installs it: `uv sync --extra <extra>`

    def __init_subclass__(cls, kind: str = "", sdk_module: str = "", extra: str = "", **kwargs: Any):
        super().__init_subclass__(**kwargs)
        for key, value in (("kind", kind), ("sdk_module", sdk_module), ("extra", extra)):
            if value:
                setattr(cls, key, value)
        if "Settings" not in cls.__dict__:  # the S of `Device[S]`, or of a generic plugin base's `[S]`
            for base in cls.__dict__.get("__orig_bases__", ()):
                origin, args = typing.get_origin(base), typing.get_args(base)
                if isinstance(origin, type) and issubclass(origin, Device) and args and isinstance(args[0], type):
                    cls.Settings = args[0]

    def __init__(self, name: str, settings: S, context: DeviceContext):
        self.name = name
        self.settings: S = settings
        self.context = context

    def topic(self, stream: str) -> str:
        """This device's topic for `stream`, e.g. topic("hand") == "/glove/<name>/hand" on a glove."""
        return device_topic(self.kind, self.name, stream)

    @classmethod
    def sdk_installed(cls) -> bool:
        """Whether the optional SDK can be imported (True for a plugin that needs none)."""
        if not cls.sdk_module:
            return True
        try:
            return importlib.util.find_spec(cls.sdk_module) is not None
        except (ImportError, ValueError):  # ValueError: a module set to None in sys.modules
            return False

    @classmethod
    def import_sdk(cls, module: str = "") -> ModuleType:
        """The optional SDK's `module` (default: sdk_module), or a DeviceError saying which extra installs it."""
        name = module or cls.sdk_module
        try:
            return importlib.import_module(name)
        except ImportError:
            raise DeviceError(f"cannot import {name}: the SDK is not installed; install the extra: "
                              f"`uv sync --extra {cls.extra}`", f"{cls.kind} plugin {cls.__name__}") from None

    @abstractmethod
    def streams(self) -> list[StreamSpec]:
        """The streams this device will produce (known before connecting)."""

    @abstractmethod
    def connect(self) -> None:
        """Open the device; raise DeviceError with a clear message if it cannot be opened."""

    @abstractmethod
    def read(self, timeout_s: float) -> list[Sample]:
        """The next samples (an empty list if nothing arrived within timeout_s); DeviceError on a fault.

        Each payload's stamp_ns is the acquisition time converted to the session clock.
        """

    def disconnect(self) -> None:
        """Close the device; must be safe to call twice and after a failed connect."""

    def endpoint(self) -> str:
        """Where connect() reaches the hardware, for messages: e.g. "UDP 127.0.0.1:39539", "xArm
        192.168.1.222", "serial /dev/ttyUSB0"; "" for a device without one (a simulation)."""
        return ""

    def operator_urls(self) -> list[str]:
        """Addresses the operator opens to use the device (an XR page), known once connected; [] for most.
        `teleprev record` and `devices check` print them, with a QR code."""
        return []

    def counters(self) -> dict[str, int]:
        """Running totals of input the device skipped (e.g. {"malformed_packets": 3}) and, named "lost_...",
        of input it knows it lost before reading it (e.g. {"lost_socket_overruns": 40}); the runner reports
        increases as "skipped" events and shows them. Must be cheap and safe to call from another thread."""
        return {}


class Actuator(Device[S]):
    """An arm or an end effector: state in through read(), position commands out through send().

    Commands reaching send() are already inside the joint limits, under the velocity limits and (for a
    hand) free of self-collision: the pipeline's command guard sees to that. In preview mode send() is
    never called.

    `own_process = True` lets a recording run the actuator in a process of its own with the command
    sender's real-time priority (teleprev/live/core/actuator_host.py), so that its commands reach the wire
    on time whatever else the session does. Such a plugin is opened, read and sent to only in that process,
    on a copy of the object the rig built (forked before it connected): it must share nothing with the
    rig's other devices (`context.shared`, `context.task_listeners`, `context.operator`), and its samples
    are JointSample, PoseSample or Event. Left False, it runs in the session process as every device does.
    """

    joint_names: tuple[str, ...] = ()
    own_process: ClassVar[bool] = False

    @abstractmethod
    def send(self, command: JointSample) -> None:
        """Move towards the named joint positions (the latest command wins)."""
