"""The sim devices on a physics rig ([sim] world = "physics"): the rig key, sim.arm and sim.hand commanding
into and measuring from the one physics world (in its own process), sim.camera rendering it with depth,
and a faulting arm command never reaching the world."""

from __future__ import annotations

import subprocess
import sys
import time
from dataclasses import replace

import cv2
import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.errors import ConfigError, DeviceError
from teleprev.messages import JointSample
from teleprev.rig import default_rig_path, load_rig
from teleprev.world.places import ARM_HOME
from tests.helpers.wait import wait_until

PHYSICS_RIG = default_rig_path().parent / "sim_physics.toml"


def test_loading_a_physics_rig_imports_no_physics_engine():
    code = ("import sys; from teleprev.rig import load_rig; from teleprev.clock import SessionClock; "
            f"load_rig({str(PHYSICS_RIG)!r}).device_context(SessionClock()); print('mujoco' in sys.modules)")
    ran = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert ran.stdout.strip() == "False", ran.stderr


def test_the_sim_key_selects_the_world_and_kinematic_stays_the_default(tmp_path):
    assert load_rig().sim.world == "kinematic"
    assert load_rig().device_context(SessionClock()).physics is None
    rig = load_rig(PHYSICS_RIG)
    assert (rig.sim.world, rig.sim.rate_hz) == ("physics", 500.0)
    context = rig.device_context(SessionClock())
    assert context.physics is not None and not context.physics.started  # started when a device first uses it
    bad = tmp_path / "bad.toml"
    text = PHYSICS_RIG.read_text()
    bad.write_text(text.replace('world = "physics"', 'world = "mujoco"'))
    with pytest.raises(ConfigError, match=r"\[sim\]\.world"):
        load_rig(bad)
    bad.write_text(text.replace("rate_hz = 500.0                  # physics", "rate_hz = 100.0 #"))
    with pytest.raises(ConfigError, match=r"\[sim\].*rate_hz must be 500..10000"):
        load_rig(bad)


@pytest.fixture
def physics_devices():
    """The physics rig's arm, hand and camera, connected to one world; closed after the test."""
    rig = load_rig(PHYSICS_RIG)
    rig = replace(rig, devices={n: replace(d, settings=replace(d.settings, depth=True)) if d.kind == "camera" else d
                                for n, d in rig.devices.items()})
    context = rig.device_context(SessionClock())
    devices = {d.kind: d.cls(d.name, d.settings, context) for d in rig.devices.values()
               if d.kind in ("arm", "hand", "camera")}
    for d in devices.values():
        d.connect()
    yield devices, context.physics
    for d in devices.values():
        d.disconnect()
    context.physics.close()


def _min_jerk(s: float) -> float:
    s = min(max(s, 0.0), 1.0)
    return s ** 3 * (10 - 15 * s + 6 * s * s)


def test_arm_and_hand_command_into_and_measure_from_the_world(physics_devices):
    devices, physics = physics_devices
    arm, hand, camera = devices["arm"], devices["hand"], devices["camera"]
    link = physics.link()
    assert physics.started and link.joint_state(arm.joint_names)[1] == pytest.approx(ARM_HOME, abs=5e-3)

    # the arm: a smooth 0.2 rad move of joint1 in 0.8 s, within its acceleration and jerk limits
    clock = arm.context.clock
    start, home = clock.now_ns(), np.array(ARM_HOME)
    while (t := clock.now_ns()) < start + 1_000_000_000:
        q = home.copy()
        q[0] += 0.2 * _min_jerk((t - start) / 0.8e9)
        arm.send(JointSample(t, arm.joint_names, q))
        hand.send(JointSample(t, ("1", "5"), np.array([0.8, 0.6])))
        time.sleep(0.01)
    assert not arm.fault

    def measured(device, names):
        samples = [s.payload for s in device.read(0.1)]
        last = samples[-1] if samples else None
        return None if last is None else dict(zip(last.names, last.positions))

    wait_until(lambda: abs(measured(arm, arm.joint_names)["joint1"] - 0.2) < 0.01, 3.0, what="the arm reaching 0.2 rad")
    wait_until(lambda: abs(measured(hand, hand.joint_names)["1"] - 0.8) < 0.05, 3.0, what="finger 1 reaching 0.8 rad")
    # what the devices report is the world's own measurement
    assert link.joint_positions(("joint1",))["joint1"] == pytest.approx(0.2, abs=0.01)

    # the camera renders the world (JPEG of the rig's size) and keeps its depth in metres
    frames = []
    wait_until(lambda: frames.extend(camera.read(0.2)) or frames, 10.0, what="a camera frame")
    image = cv2.imdecode(np.frombuffer(frames[0].payload.data, np.uint8), cv2.IMREAD_COLOR)
    assert image.shape == (480, 640, 3) and image.std() > 10
    depth = camera.last_depth
    assert depth.shape == (480, 640) and 0.5 < float(np.median(depth[depth > 0])) < 4.0


def test_a_command_that_faults_the_arm_never_reaches_the_world(physics_devices):
    devices, physics = physics_devices
    arm = devices["arm"]
    link = physics.link()
    clock = arm.context.clock
    home = np.array(ARM_HOME)
    t = clock.now_ns()
    arm.send(JointSample(t, arm.joint_names, home))
    jump = home.copy()
    jump[1] += 0.05  # 5 cm of a step in 10 ms: far past 10 rad/s^2
    arm.send(JointSample(t + 10_000_000, arm.joint_names, jump))
    assert "controller fault" in arm.fault
    assert link.targets(("joint2",))[0] == pytest.approx(home[1], abs=5e-3)  # held where it stood
    with pytest.raises(DeviceError, match="controller fault"):
        arm.send(JointSample(t + 20_000_000, arm.joint_names, home))
    time.sleep(0.2)
    assert link.joint_positions(("joint2",))["joint2"] == pytest.approx(home[1], abs=5e-3)
