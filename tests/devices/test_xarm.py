"""xarm.arm through a test double at the XArmLink interface (the real SDK against the emulated controller:
test_xarm_emulated.py)."""

from __future__ import annotations

import sys
import time

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.devices.runner import DeviceRunner
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample
from teleprev_devices.xarm import SdkXArmLink, XArm, XArmSettings
from tests.helpers.wait import wait_until

HOME = [0.0, -0.27, -0.11, 0.0, -0.85, -1.571]
NAMES = tuple(f"joint{i}" for i in range(1, 7))


class LinkDouble:
    """Records every call; `unplugged` makes every call fail as a lost connection would."""

    def __init__(self, angles=HOME, extra=(0.0,), table=None):
        self.calls: list[tuple] = []
        self.table = table  # the arm's own joint limits, as the SDK's table gives them
        self.angles = list(angles) + list(extra)  # the SDK reports 7 values for a 6-joint arm
        self.unplugged = False

    def _call(self, *call):
        if self.unplugged:
            raise DeviceError("connection lost", "xArm double")
        self.calls.append(call)

    def connect(self):
        self._call("connect")

    def joint_limits(self):
        return self.table

    def enable_servo_mode(self):
        self._call("enable_servo_mode")

    def joint_angles(self):
        self._call("joint_angles")
        return self.angles[:6]

    def servo_angle_j(self, angles):
        self._call("servo_angle_j", tuple(angles))

    def disconnect(self):
        self.calls.append(("disconnect",))


def arm(link, **kw):
    return XArm("arm", XArmSettings(host="10.0.0.2", **kw), DeviceContext(SessionClock()), link=link)


def cmd(values, names=NAMES):
    return JointSample(0, tuple(names), np.array(values, dtype=float))


def test_connect_enables_servo_mode_and_reads_state():
    link = LinkDouble()
    a = arm(link)
    a.connect()
    assert [c[0] for c in link.calls] == ["connect", "enable_servo_mode", "joint_angles"]
    samples = a.read(0.1)
    assert samples[0].topic == "/arm/arm/state"
    assert samples[0].payload.names == NAMES and np.allclose(samples[0].payload.positions, HOME)
    a.disconnect()
    a.disconnect()  # safe twice
    assert [c[0] for c in link.calls].count("disconnect") == 1


def test_commands_are_checked_then_streamed_in_radians():
    link = LinkDouble()
    a = arm(link, max_acceleration=1e9, max_jerk=1e12)  # these commands jump; the stream rule has its own test
    a.connect()
    target = np.array(HOME) + 0.05
    a.send(cmd(target))
    assert link.calls[-1] == ("servo_angle_j", tuple(target))
    # a partial command keeps the other joints at the previous target
    a.send(cmd([0.1], names=["joint1"]))
    assert link.calls[-1][1] == (0.1, *target[1:])
    sent = len(link.calls)
    bad = [
        (cmd([np.nan] + HOME[1:]), "non-finite positions for joint1"),
        (cmd(HOME[:2] + [0.25] + HOME[3:]), r"joint3=0.2500 not in \[-3.1102, 0.1920\]"),  # xArm6 J3 upper limit
        (cmd([0.1 + 0.3] + list(target[1:])), "joint1 would jump 0.300 rad"),
        (cmd([0.0], names=["joint9"]), "unknown joints"),
    ]
    for command, message in bad:
        with pytest.raises(DeviceError, match=message):
            a.send(command)
    assert len(link.calls) == sent  # nothing refused reached the controller
    assert a.counters() == {"refused_commands": 4}


def test_state_is_polled_at_no_more_than_the_rate():
    link = LinkDouble()
    a = arm(link, rate_hz=50.0)
    a.connect()
    t0 = time.monotonic()
    n = 0
    while time.monotonic() - t0 < 0.3:
        n += len(a.read(0.02))
    assert 13 <= n <= 17


def test_a_lost_connection_is_a_device_error_and_the_runner_reconnects():
    link = LinkDouble()
    a = arm(link)
    events = []
    clock = a.context.clock
    runner = DeviceRunner(a, lambda s, t: events.append(s), clock, reconnect_s=0.05)
    runner.start()
    wait_until(lambda: runner.connected, 5, what="the runner connected")
    link.unplugged = True
    with pytest.raises(DeviceError):
        wait_until(lambda: a.send(cmd(HOME)), 5, what="the unplugged link's DeviceError")
    time.sleep(0.2)  # reconnect attempts while unplugged
    link.unplugged = False
    wait_until(lambda: runner.stats().connects == 2, 5, what="the reconnect")
    runner.stop()
    kinds = [s.payload.data["event"] for s in events if s.topic == "/events/device"]
    assert kinds[:3] == ["connected", "error", "disconnected"] and "connected" in kinds[3:]
    assert runner.stats().connects == 2
    assert [c[0] for c in link.calls].count("enable_servo_mode") == 2  # servo mode again after reconnecting


def test_seven_joints_need_a_seven_joint_urdf():
    with pytest.raises(ConfigError, match="has no joints joint7"):
        XArm("arm", XArmSettings(host="10.0.0.2", dof=7), DeviceContext(SessionClock()), link=LinkDouble())
    ctx = DeviceContext(SessionClock(), robot="xarm7")
    a = XArm("arm", XArmSettings(host="10.0.0.2", dof=7), ctx, link=LinkDouble(angles=[0.0] * 7, extra=()))
    assert a.joint_names[-1] == "joint7"


def test_settings_errors_name_the_table(tmp_path):
    from teleprev.rig import load_rig

    rig = tmp_path / "rig.toml"
    rig.write_text('[devices.arm]\nplugin = "xarm.arm"\n')
    with pytest.raises(ConfigError, match=r"rig.toml \[devices.arm\]: host is required"):
        load_rig(rig)
    rig.write_text('[devices.arm]\nplugin = "xarm.arm"\nhost = "10.0.0.2"\nrate_hz = 250.0\n')
    with pytest.raises(ConfigError, match=r"rate_hz must be in \(0, 100\]"):
        load_rig(rig)


def test_missing_sdk_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "xarm", None)  # as if xarm-python-sdk were not installed
    monkeypatch.setitem(sys.modules, "xarm.wrapper", None)
    with pytest.raises(DeviceError, match=r"uv sync --extra xarm"):
        SdkXArmLink("10.0.0.2", 6).connect()


def test_the_arms_own_joint_limits_narrow_the_urdfs_before_any_command():
    xi1305 = [(-6.28, 6.28), (-2.042035, 2.024581), (-3.822271, 0.174532), (-6.28, 6.28), (-1.692969, 3.14),
              (-6.28, 6.28)]
    link = LinkDouble(table=xi1305)
    a = arm(link)
    a.connect()
    assert a.limits.upper[1] == pytest.approx(2.024581) and a.limits.upper[2] == pytest.approx(0.174532)
    assert a.limits.lower[0] == pytest.approx(-3.11018)  # the URDF's, where it is the narrower
    q = np.array(HOME)
    q[2] = 0.18  # inside the URDF's 0.19198, past this arm's 0.174532
    with pytest.raises(DeviceError, match=r"outside the joint limits: joint3=0.1800 not in \[-3.1102, 0.1745\]"):
        a.send(cmd(q))
    assert not [c for c in link.calls if c[0] == "servo_angle_j"]
