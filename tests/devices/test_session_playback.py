"""replay.*: streams of a real recorded MCAP session played back as live devices."""

from __future__ import annotations

import time

import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.errors import ConfigError
from teleprev.human.smplx import HAND_POSE_NAMES
from teleprev.messages import JointSample, Logged, PoseSample
from teleprev_devices.session_playback import ReplayArm, ReplayGlove, ReplaySettings, ReplaySuit

T0 = 1_700_000_000_000_000_000
PERIOD = 10_000_000  # 100 Hz
N = 30
LATENCY = 3_000_000


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    from teleprev.session.recorder import Recorder

    path = tmp_path_factory.mktemp("replay") / "recorded.mcap"
    rec = Recorder(path).start()
    for k in range(N):
        t = T0 + k * PERIOD
        rec.log(Logged("/glove/right/hand", t, JointSample(t - LATENCY, HAND_POSE_NAMES, np.full(45, k * 0.01))))
        if k % 2 == 0:
            rec.log(
                Logged(
                    "/suit/s1/wrist",
                    t + 1,
                    PoseSample(t - 2 * LATENCY, "suit", np.array([k, 0.0, 1.0]), np.array([0, 0, 0, 1.0])),
                )
            )
            rec.log(Logged("/suit/s2/wrist", t + 2, PoseSample(t, "suit", np.zeros(3), np.array([0, 0, 0, 1.0]))))
        rec.log(Logged("/arm/arm/state", t + 3, JointSample(t, ("joint1", "joint2"), np.array([k, -k], dtype=float))))
    rec.close()
    return path


def play(device, seconds):
    device.connect()
    out, end = [], time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            out.extend(device.read(0.02))
    finally:
        device.disconnect()
    return out


def test_a_recorded_glove_plays_back_in_real_time_restamped_on_this_clock(session):
    clock = SessionClock()
    glove = ReplayGlove("glove", ReplaySettings(session=session.name), DeviceContext(clock, rig_dir=session.parent))
    assert [(s.topic, round(s.rate_hz)) for s in glove.streams()] == [("/glove/glove/hand", 100)]
    start = clock.now_ns()
    got = play(glove, N * PERIOD / 1e9 + 0.15)
    assert len(got) == N and {s.topic for s in got} == {"/glove/glove/hand"}
    values = [s.payload.positions[0] for s in got]
    assert np.allclose(values, np.arange(N) * 0.01)  # the recorded values, in order
    stamps = np.array([s.payload.stamp_ns for s in got])
    assert np.all(np.diff(stamps) == PERIOD)  # the original spacing
    assert abs(stamps[0] - (start - LATENCY)) < 20_000_000  # on this session's clock, latency kept
    assert got[0].payload.names == HAND_POSE_NAMES


def test_speed_and_loop(session):
    clock = SessionClock()
    glove = ReplayGlove("g", ReplaySettings(session=str(session), speed=2.0, loop=True), DeviceContext(clock))
    got = play(glove, 0.25)  # one pass takes ~0.15 s at double speed
    assert N + 5 < len(got) < 2 * N + 5
    stamps = np.array([s.payload.stamp_ns for s in got])
    assert np.all(np.diff(stamps[:N]) == PERIOD // 2)
    assert got[N].payload.positions[0] == 0.0 and stamps[N] > stamps[N - 1]  # round again, time goes on


def test_one_device_out_of_several_and_arm_commands(session):
    ctx = DeviceContext(SessionClock())
    with pytest.raises(ConfigError, match=r"\[devices.suit\].*2 suit devices \(s1, s2\).*device ="):
        ReplaySuit("suit", ReplaySettings(session=str(session)), ctx)
    suit = ReplaySuit("suit", ReplaySettings(session=str(session), device="s1"), ctx)
    got = play(suit, 0.4)
    assert len(got) == N // 2 and got[3].topic == "/suit/suit/wrist"
    assert got[3].payload.position[0] == 6.0

    arm = ReplayArm("arm", ReplaySettings(session=str(session), topic="/arm/arm/state"), ctx)
    assert arm.joint_names == ("joint1", "joint2")
    arm.send(JointSample(0, arm.joint_names, np.zeros(2)))
    assert arm.commands == 1


def test_bad_settings_name_what_and_where(session, tmp_path):
    ctx = DeviceContext(SessionClock(), rig_dir=tmp_path)
    with pytest.raises(ConfigError, match=r"\[devices.g\].session: cannot play back .*nope.mcap: no such session file"):
        ReplayGlove("g", ReplaySettings(session="nope.mcap"), ctx)
    with pytest.raises(
        ConfigError, match=r"\[devices.g\].device: no glove device 'left'.*recorded glove devices: right"
    ):
        ReplayGlove("g", ReplaySettings(session=str(session), device="left"), ctx)
    with pytest.raises(ConfigError, match=r"'/suit/s1/wrist' is not a glove stream"):
        ReplayGlove("g", ReplaySettings(session=str(session), topic="/suit/s1/wrist"), ctx)
    with pytest.raises(ValueError, match="session is required"):
        ReplaySettings()
