"""xarm.arm: a UFactory xArm (6 or 7 joints) in servo mode through xarm-python-sdk (`uv sync --extra xarm`).

    [devices.arm]
    plugin = "xarm.arm"
    host = "192.168.1.185"     # the control box
    dof = 6
    rate_hz = 100.0            # joint state samples, from the controller's 100 Hz report (port 30003)

The plugin talks to the controller through XArmLink, a small interface; SdkXArmLink is the real one
(xarm.wrapper.XArmAPI, imported when the device connects). Servo mode is motion_enable + set_mode(1) +
set_state(0); commands are streamed with set_servo_angle_j in radians and the controller runs the latest
one at once, so every command is checked here first: finite, inside the joint limits, at most
max_step_rad from the previous target, and (on the commands' stamps) under the acceleration and jerk
limits of a servo-mode stream (teleprev.devices.ServoStreamRule, the rule the sim arm faults by).

The joint limits are the URDF's intersected, on every connect, with the connected arm's own: the SDK's
table for its series (an SN from XI1305 on has joint2 <= 2.0246 and joint3 <= 0.1745 rad;
xarm/core/config/x_config.py), which the SDK enforces by refusing a target (code -8).

Requests stay within UFactory's rates (at most 250 requests a second on port 502, state at <= 100 Hz):
joint states come from the real-time report the controller pushes at 100 Hz on port 30003, not from
requests; port 502 carries the commands and an error-code read every error_check_every-th sample.

A fault stops the commands and is one line naming it: a controller error with its code and meaning
(collision, joint limit, e-stop: cleared on the arm by the operator, never from here), a lost
connection, a report stream gone quiet for report_timeout_s, a reply slower than reply_timeout_s.
`teleprev devices emulate xarm` runs an emulated controller to try a rig against.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from teleprev.devices import DeviceContext, DeviceError, DeviceFault, JointLimits, PolledActuator, ServoStreamRule

# What the SDK's own return codes mean (xarm.x3.code.APIState), in words for the operator.
SDK_CODES = {
    -1: "not connected",
    -2: "the arm is not enabled",
    -8: "a value is out of range",
    1: "the controller has an error latched",
    2: "the controller has a warning latched",
    3: "no reply in time",
    4: "a reply of the wrong length", 5: "a reply out of sequence", 6: "a reply of another protocol",
    7: "a reply to another command",
    8: "the command could not be sent (connection lost)",
    9: "the arm is not ready to move",
    10: "the controller refused the command as invalid",
    12: "a parameter the controller refused",
}


class XArmLink(Protocol):
    """The controller as the plugin needs it. Every call raises DeviceError on failure."""

    def connect(self) -> None: ...
    def joint_limits(self) -> list[tuple[float, float]] | None: ...  # the connected arm's own, radians
    def enable_servo_mode(self) -> None: ...
    def joint_angles(self) -> list[float]: ...  # radians, joint1.. (at least dof values)
    def servo_angle_j(self, angles: list[float]) -> None: ...  # radians, dof values
    def disconnect(self) -> None: ...


def sdk_joint_limits(api) -> list[tuple[float, float]] | None:
    """The joint limits the SDK enforces for the connected arm: its table row for the arm's series, chosen
    as xarm/x3/xarm.py _is_out_of_joint_range chooses it (an SN from XI1305 up to 8500 uses the "_1305" row)."""
    from xarm.core.config.x_config import XCONF

    sn = api.sn or ""
    series = int(sn[2:6]) if sn[2:6].isdigit() else 0
    device_type = int(f"{api.axis}1305") if 1305 <= series < 8500 else api.device_type
    return XCONF.Robot.JOINT_LIMITS.get(api.axis, {}).get(device_type)


def intersect_limits(urdf: JointLimits, arm: list[tuple[float, float]] | None) -> JointLimits:
    """The URDF's joint limits narrowed to the arm's own (None: the arm has no table, the URDF's stand)."""
    if not arm:
        return urdf
    table = np.array(arm[:len(urdf.names)], dtype=float)
    return JointLimits(urdf.names, np.maximum(urdf.lower, table[:, 0]), np.minimum(urdf.upper, table[:, 1]))


class SdkXArmLink:
    """XArmLink over xarm.wrapper.XArmAPI (`api_factory`: a subclass of it, say).

    The controller pushes the real-time report (state, mode, joint angles, TCP pose) every 10 ms on port
    30003, which the SDK reads on its own thread; joint angles come from it. A report older than
    `report_timeout_s` is a fault, since the arm's state would then go unseen. The error code, which that
    report does not carry, is read every `error_check_every`-th sample and after any refused command.
    Every request waits at most `reply_timeout_s` for its reply.
    """

    def __init__(self, host: str, dof: int, api_factory: Callable | None = None, reply_timeout_s: float = 0.1,
                 report_timeout_s: float = 1.0, error_check_every: int = 10):
        self.host = host
        self.dof = dof
        self.where = f"xArm controller {host}"
        self.reply_timeout_s = reply_timeout_s
        self.report_timeout_s = report_timeout_s
        self.error_check_every = error_check_every
        self._factory = api_factory
        self.api = None
        self._last_report = 0.0
        self._reported: list[float] | None = None
        self._first_report = threading.Event()
        self._reads = 0

    def _on_report(self, report: dict) -> None:
        self._reported = list(report["joints"])
        self._last_report = time.monotonic()
        self._first_report.set()

    def _controller_error(self, code: int) -> str:
        try:
            from xarm.core.config.x_code import ControllerError

            meaning = ControllerError(code).title["en"]
        except Exception:  # an SDK without the table still gets the code
            meaning = "see the controller's error table"
        return f"controller error {code}: {meaning}"

    def _fail(self, call: str, code: int) -> DeviceError:
        """The DeviceError for an SDK call that returned `code`: the controller's own error where it has one."""
        if code == 1 or (code == 9 and self.api is not None and self.api.connected):
            status, (error, _warn) = self.api.get_err_warn_code()
            if status == 0 and error:
                return DeviceError(f"{self._controller_error(error)}; the arm stopped (clear it on the arm once "
                                   "you know why, then reconnect)", self.where)
        if code in (-1, 8) or (self.api is not None and not self.api.connected):
            return DeviceError("connection lost: the controller closed TCP port 502 (power, cable, or another "
                               "client took over)", self.where)
        if code == 3:
            return DeviceError(f"{call}: no reply within {self.reply_timeout_s:g} s (SDK code 3): the controller is "
                               "slow, or the connection is gone", self.where)
        return DeviceError(f"{call} returned SDK code {code} ({SDK_CODES.get(code, 'see xarm.x3.code.APIState')})",
                           self.where)

    def _check(self, code, call: str) -> None:
        if code != 0:
            raise self._fail(call, code)

    def connect(self) -> None:
        factory = self._factory or XArm.import_sdk("xarm.wrapper").XArmAPI
        try:
            self.api = factory(self.host, is_radian=True, do_not_open=True, report_type="real")
            self.api.connect()
        except Exception as exc:
            self.api = None
            raise DeviceError(f"cannot connect ({exc}; is the control box on and reachable on port 502?)",
                              self.where) from None
        if not self.api.connected:
            raise DeviceError("cannot connect (is the control box on and reachable on port 502?)", self.where)
        axis = self.api.axis
        if axis != self.dof:
            self.disconnect()
            raise DeviceError(f"the controller drives a {axis}-joint arm but the rig says dof = {self.dof}", self.where)
        self._last_report = time.monotonic()  # the report stream has report_timeout_s to start
        self._reported = None
        self._first_report.clear()
        self.api.register_report_callback(self._on_report, report_joints=True)
        self.api.set_timeout(self.reply_timeout_s)
        if not self._first_report.wait(self.report_timeout_s):
            self.disconnect()
            raise DeviceError(
                f"the controller's report stream (port 30003) sent nothing in {self.report_timeout_s:g} s "
                "after connecting",
                self.where,
            )

    def joint_limits(self) -> list[tuple[float, float]] | None:
        return sdk_joint_limits(self.api)

    def enable_servo_mode(self) -> None:
        # An error the controller latched (collision, limit, e-stop) is the operator's to clear, on purpose:
        # clearing it from here could restart an arm that just stopped for a reason.
        status, (error, _warn) = self.api.get_err_warn_code()
        self._check(status, "get_err_warn_code")
        if error:
            raise DeviceError(f"{self._controller_error(error)}; clear it on the arm (UFactory Studio or "
                              "clean_error) once you know why it stopped", self.where)
        self._check(self.api.motion_enable(enable=True), "motion_enable(True)")
        self._check(self.api.set_mode(1), "set_mode(1)")
        self._check(self.api.set_state(0), "set_state(0)")

    def _healthy(self) -> None:
        if not self.api.connected:
            raise self._fail("", -1)
        silent = time.monotonic() - self._last_report
        if silent > self.report_timeout_s:
            raise DeviceError(f"the controller's report stream (port 30003) sent nothing for {silent:.1f} s "
                              f"(limit {self.report_timeout_s:g} s): the arm's state would go unseen", self.where)
        self._reads += 1
        if self._reads % self.error_check_every == 0:
            status, (error, _warn) = self.api.get_err_warn_code()
            self._check(status, "get_err_warn_code")
            if error:
                raise DeviceError(f"{self._controller_error(error)}; the arm stopped (clear it on the arm once "
                                  "you know why, then reconnect)", self.where)

    def joint_angles(self) -> list[float]:
        self._healthy()
        return list(self._reported)[: self.dof]

    def servo_angle_j(self, angles: list[float]) -> None:
        if not self.api.connected:
            raise self._fail("set_servo_angle_j", -1)
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
    max_acceleration: float = 10.0  # rad/s^2 and rad/s^3: a command stream past these (+10%, on the commands'
    max_jerk: float = 500.0  # stamps) stops the commands, as it would fault the sim arm
    reply_timeout_s: float = 0.1  # a controller reply slower than this is a fault (it answers in a few ms)
    report_timeout_s: float = 1.0  # the report stream (100 Hz) silent for this long is a fault
    error_check_every: int = 10  # samples between reads of the error code (10 Hz at 100 Hz)

    def __post_init__(self):
        if not self.host:
            raise ValueError("host is required: the control box's IP address, e.g. host = \"192.168.1.185\"")
        if self.dof not in (6, 7):
            raise ValueError(f"dof must be 6 or 7, got {self.dof}")
        if not 0 < self.rate_hz <= 100:
            raise ValueError(f"rate_hz must be in (0, 100] (the controller reports at 100 Hz), got {self.rate_hz}")
        if not 1 <= self.error_check_every <= 100:
            raise ValueError(f"error_check_every must be 1..100, got {self.error_check_every}")
        if not 0 < self.max_step_rad <= 0.5:
            raise ValueError(f"max_step_rad must be in (0, 0.5], got {self.max_step_rad}")
        if not (self.max_acceleration > 0 and self.max_jerk > 0):
            raise ValueError(
                f"max_acceleration and max_jerk must be > 0, got {self.max_acceleration} and {self.max_jerk}"
            )
        if not (0 < self.reply_timeout_s <= 5 and 0 < self.report_timeout_s <= 10):
            raise ValueError("reply_timeout_s must be in (0, 5] and report_timeout_s in (0, 10], got "
                             f"{self.reply_timeout_s} and {self.report_timeout_s}")


class XArm(PolledActuator[XArmSettings], kind="arm", sdk_module="xarm", extra="xarm"):
    """JointSample of joint1..jointN on /arm/<name>/state; send() streams servo targets."""

    own_process = True  # a recording writes its targets from a paced process of its own (Actuator)

    def __init__(self, name: str, settings: XArmSettings, context: DeviceContext, link: XArmLink | None = None):
        super().__init__(name, settings, context, context.robot, tuple(f"joint{i}" for i in range(1, settings.dof + 1)),
                         where=f"device {name!r} (xArm {settings.host})")
        self.link: XArmLink = link or SdkXArmLink(settings.host, settings.dof, reply_timeout_s=settings.reply_timeout_s,
                                                  report_timeout_s=settings.report_timeout_s,
                                                  error_check_every=settings.error_check_every)
        self.urdf_limits = self.limits
        self.rule = ServoStreamRule(self.joint_names, settings.max_acceleration, settings.max_jerk, self.period_ns)

    def endpoint(self) -> str:
        return f"xArm {self.settings.host}"

    def _open(self) -> None:
        self.link.connect()
        self.limits = intersect_limits(self.urdf_limits, self.link.joint_limits())

    def _start(self) -> np.ndarray:
        self.link.enable_servo_mode()
        self.rule.reset()
        return self._poll()

    def _close(self) -> None:
        self.link.disconnect()

    def _poll(self) -> np.ndarray:
        q = np.asarray(self.link.joint_angles(), dtype=float)
        if q.shape != (len(self.joint_names),) or not np.all(np.isfinite(q)):
            raise DeviceError(f"the controller sent an unusable joint state {q.tolist()}", self.where)
        return q

    def _refuse(self, target: np.ndarray, stamp_ns: int) -> None:
        step = np.abs(target - self._target)
        if step.max() > self.settings.max_step_rad:
            j = int(step.argmax())
            raise DeviceError(f"command refused: {self.joint_names[j]} would jump {step[j]:.3f} rad "
                              f"(max_step_rad = {self.settings.max_step_rad:g})", self.where)
        broken = self.rule.check(stamp_ns, target, lambda: (self._target, np.zeros_like(self._target)))
        if broken:
            raise DeviceFault(f"command refused, commands stopped: {broken.describe()}, which would fault the "
                              "controller; nothing more is sent until the arm is reconnected", self.where)

    def _write(self, target: np.ndarray) -> None:
        self.link.servo_angle_j(target.tolist())
