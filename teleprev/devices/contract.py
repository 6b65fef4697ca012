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

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar

from teleprev.messages import JointSample, Sample
from teleprev.robot.effectors import EndEffector, end_effector
from teleprev.clock import SessionClock

KINDS = ("glove", "suit", "camera", "arm", "hand")


@dataclass(frozen=True)
class StreamSpec:
    """A stream a device produces: its topic, payload type ("joints", "pose", "image") and nominal rate."""

    topic: str
    payload: str
    rate_hz: float


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

    @property
    def effector(self) -> EndEffector:
        """The end effector's row of the one table (joints, TCP link, grasp point)."""
        return end_effector(self.end_effector)


@dataclass
class NoSettings:
    pass


class Device(ABC):
    """A source of timestamped samples. Subclasses set `kind` and `Settings` (a dataclass)."""

    kind: ClassVar[str]
    Settings: ClassVar[type] = NoSettings

    def __init__(self, name: str, settings: Any, context: DeviceContext):
        self.name = name
        self.settings = settings
        self.context = context

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

    def counters(self) -> dict[str, int]:
        """Running totals of input the device skipped (e.g. {"malformed_packets": 3}); the runner reports
        increases as error events and shows them. Must be cheap and safe to call from another thread."""
        return {}


class Actuator(Device):
    """An arm or an end effector: state in through read(), position commands out through send().

    Commands reaching send() are already inside the joint limits, under the velocity limits and (for a
    hand) free of self-collision: the pipeline's command guard sees to that. In preview mode send() is
    never called.
    """

    joint_names: tuple[str, ...] = ()

    @abstractmethod
    def send(self, command: JointSample) -> None:
        """Move towards the named joint positions (the latest command wins)."""
