"""xarm.arm: a UFactory xArm (6 or 7 joints) in servo mode through xarm-python-sdk (`uv sync --extra xarm`).

    [devices.arm]
    plugin = "xarm.arm"
    host = "192.168.1.185"     # the control box
    dof = 6
    rate_hz = 100.0            # joint state polling (the controller is best polled at <= 100 Hz)

The plugin talks to the controller through XArmLink, a five-call interface; SdkXArmLink is the real
one (xarm.wrapper.XArmAPI, imported when the device connects). Servo mode is motion_enable +
set_mode(1) + set_state(0); commands are streamed with set_servo_angle_j in radians and the controller
runs the latest one at full speed, so every command is checked here first: finite, inside the URDF's
limits, and at most max_step_rad from the previous target (refused and counted otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from teleprev.devices import DeviceContext, DeviceError, PolledActuator


class XArmLink(Protocol):
    """The controller as the plugin needs it. Every call raises DeviceError on failure."""

    def connect(self) -> None: ...
    def enable_servo_mode(self) -> None: ...
    def joint_angles(self) -> list[float]: ...  # radians, joint1.. (at least dof values)
    def servo_angle_j(self, angles: list[float]) -> None: ...  # radians, dof values
    def disconnect(self) -> None: ...


class SdkXArmLink:
    """XArmLink over xarm.wrapper.XArmAPI. `api_factory` stands in for XArmAPI (tests)."""

    def __init__(self, host: str, dof: int, api_factory: Callable | None = None):
        self.host = host
        self.dof = dof
        self.where = f"xArm controller {host}"
        self._factory = api_factory
        self.api = None

    def _check(self, code, call: str) -> None:
        if code != 0:
            raise DeviceError(f"{call} returned code {code} (controller error {getattr(self.api, 'error_code', '?')})", self.where)

    def connect(self) -> None:
        factory = self._factory or XArm.import_sdk("xarm.wrapper").XArmAPI
        try:
            self.api = factory(self.host, is_radian=True, do_not_open=True)
            self.api.connect()
        except Exception as exc:
            raise DeviceError(f"cannot connect ({exc})", self.where) from None
        if not self.api.connected:
            raise DeviceError("cannot connect (is the control box on and reachable on port 502?)", self.where)
        axis = getattr(self.api, "axis", self.dof)
        if axis != self.dof:
            self.disconnect()
            raise DeviceError(f"the controller drives a {axis}-joint arm but the rig says dof = {self.dof}", self.where)

    def enable_servo_mode(self) -> None:
        # An error the controller latched (collision, limit, e-stop) is the operator's to clear, on purpose:
        # clearing it from here could restart an arm that just stopped for a reason.
        if getattr(self.api, "error_code", 0):
            raise DeviceError(f"the controller reports error code {self.api.error_code}; clear it on the arm "
                              "(UFactory Studio or clean_error) and check why it stopped", self.where)
        self._check(self.api.motion_enable(enable=True), "motion_enable(True)")
        self._check(self.api.set_mode(1), "set_mode(1)")
        self._check(self.api.set_state(0), "set_state(0)")

    def joint_angles(self) -> list[float]:
        if not self.api.connected:
            raise DeviceError("connection lost", self.where)
        code, angles = self.api.get_servo_angle(is_radian=True)
        self._check(code, "get_servo_angle")
        return list(angles)[: self.dof]

    def servo_angle_j(self, angles: list[float]) -> None:
        if not self.api.connected:
            raise DeviceError("connection lost", self.where)
        self._check(self.api.set_servo_angle_j(list(angles), is_radian=True), "set_servo_angle_j")

    def disconnect(self) -> None:
        api, self.api = self.api, None
        if api is not None:
            api.disconnect()


@dataclass
class XArmSettings:
    host: str = ""
    dof: int = 6
    rate_hz: float = 100.0
    max_step_rad: float = 0.2  # largest change of any joint from one command to the next

    def __post_init__(self):
        if not self.host:
            raise ValueError("host is required: the control box's IP address, e.g. host = \"192.168.1.185\"")
        if self.dof not in (6, 7):
            raise ValueError(f"dof must be 6 or 7, got {self.dof}")
        if not 0 < self.rate_hz <= 100:
            raise ValueError(f"rate_hz must be in (0, 100] (the controller is best polled at <= 100 Hz), got {self.rate_hz}")
        if not 0 < self.max_step_rad <= 0.5:
            raise ValueError(f"max_step_rad must be in (0, 0.5], got {self.max_step_rad}")


class XArm(PolledActuator[XArmSettings], kind="arm", sdk_module="xarm", extra="xarm"):
    """JointSample of joint1..jointN on /arm/<name>/state; send() streams servo targets."""

    def __init__(self, name: str, settings: XArmSettings, context: DeviceContext, link: XArmLink | None = None):
        super().__init__(name, settings, context, context.robot, tuple(f"joint{i}" for i in range(1, settings.dof + 1)),
                         where=f"device {name!r} (xArm {settings.host})")
        self.link: XArmLink = link or SdkXArmLink(settings.host, settings.dof)

    def endpoint(self) -> str:
        return f"xArm {self.settings.host}"

    def _open(self) -> None:
        self.link.connect()

    def _start(self) -> np.ndarray:
        self.link.enable_servo_mode()
        return self._poll()

    def _close(self) -> None:
        self.link.disconnect()

    def _poll(self) -> np.ndarray:
        q = np.asarray(self.link.joint_angles(), dtype=float)
        if q.shape != (len(self.joint_names),) or not np.all(np.isfinite(q)):
            raise DeviceError(f"the controller sent an unusable joint state {q.tolist()}", self.where)
        return q

    def _refuse(self, target: np.ndarray) -> None:
        step = np.abs(target - self._target)
        if step.max() > self.settings.max_step_rad:
            j = int(step.argmax())
            raise DeviceError(f"command refused: {self.joint_names[j]} would jump {step[j]:.3f} rad "
                              f"(max_step_rad = {self.settings.max_step_rad:g})", self.where)

    def _write(self, target: np.ndarray) -> None:
        self.link.servo_angle_j(target.tolist())
