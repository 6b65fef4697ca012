"""The sim devices of the default rig, run together in real time: rates, payloads, and stamps that come
back to the session clock within a millisecond of the true acquisition time."""

import csv
import threading
import time

import cv2
import numpy as np
import pytest

from teleprev.clock import SessionClock
from teleprev.devices.contract import DeviceContext
from teleprev.errors import ConfigError, DeviceError
from teleprev.human.smplx import HAND_POSE_NAMES, hand_pose_from_angles
from teleprev.rig import load_rig
from teleprev_devices.sim.glove import GloveSettings, SimGlove
from teleprev_devices.sim.suit import SimSuit, SuitSettings

RUN_S = 1.5


def open_rig(path=None, tmp_path=None):
    rig = load_rig(path)
    ctx = DeviceContext(clock=SessionClock(), rig_dir=tmp_path or rig.dir, robot=rig.rig.robot,
                        end_effector=rig.rig.end_effector)
    devices = {name: entry.cls(name, entry.settings, ctx) for name, entry in rig.devices.items()}
    return rig, ctx, devices


def run_together(devices, seconds):
    """Each device on its own reader thread, as the session loop runs them."""
    out = {name: [] for name in devices}
    errors = []

    def reader(name, dev):
        try:
            dev.connect()
            t_end = time.monotonic() + seconds
            while time.monotonic() < t_end:
                out[name].extend(dev.read(0.05))
        except Exception as exc:  # surfaced below
            errors.append(exc)
        finally:
            dev.disconnect()

    threads = [threading.Thread(target=reader, args=item) for item in devices.items()]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors:
        raise errors[0]
    return out


@pytest.fixture(scope="module")
def default_run():
    rig, ctx, devices = open_rig()
    return rig, ctx, devices, run_together(devices, RUN_S)


def test_every_stream_comes_at_its_rate_with_stamps_within_1ms_of_the_truth(default_run):
    rig, ctx, devices, out = default_run
    truth = ctx.shared["sim.truth"]
    for name, dev in devices.items():
        (spec,) = dev.streams()
        samples = out[name]
        assert samples and all(s.topic == spec.topic for s in samples)
        stamps = np.array([s.payload.stamp_ns for s in samples])
        assert np.all(np.diff(stamps) > 0), f"{name}: stamps not increasing"
        rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9)
        assert rate == pytest.approx(spec.rate_hz, rel=0.03), f"{name}: {rate:.1f} Hz"
        assert len(samples) >= 0.8 * spec.rate_hz * (RUN_S - 0.2)
        records = truth.records(spec.topic)
        errors = np.array([s.payload.stamp_ns - truth.true_ns(s.topic, s.payload.stamp_ns) for s in samples])
        assert np.abs(errors).max() < 1_000_000, f"{name}: sync error {np.abs(errors).max() / 1e6:.3f} ms"
        # The device's own clock is far off the session clock: the conversion did real work.
        offset = np.array([r.device_ns - r.true_ns for r in records])
        assert np.abs(offset - dev.settings.clock_offset_s * 1e9).max() < 1e6
        assert abs(dev.settings.clock_offset_s) > 1.0


def test_glove_and_suit_stream_one_operator(default_run):
    rig, ctx, devices, out = default_run
    glove, suit = devices["glove"], devices["suit"]
    assert glove.operator is suit.operator is ctx.shared["sim.operator"]
    truth = ctx.shared["sim.truth"]
    for sample in out["glove"][::20]:
        p = sample.payload
        assert p.names == HAND_POSE_NAMES and p.positions.shape == (45,)
        t = glove.operator.time_s(truth.true_ns(sample.topic, p.stamp_ns))
        expected = hand_pose_from_angles(*glove.operator.hand_angles(t)).reshape(45)
        assert np.abs(p.positions - expected).max() < 0.02  # sensor noise only
    for sample in out["suit"][::10]:
        p = sample.payload
        assert p.frame_id == "suit" and np.linalg.norm(p.orientation) == pytest.approx(1.0)
        t = suit.operator.time_s(truth.true_ns(sample.topic, p.stamp_ns))
        position, _ = suit.operator.wrist(t)
        assert np.abs(p.position - position).max() < 0.005


def test_camera_frames_are_jpegs_of_the_configured_size(default_run):
    rig, ctx, devices, out = default_run
    cam = devices["cam_front"]
    frames = [cv2.imdecode(np.frombuffer(s.payload.data, np.uint8), cv2.IMREAD_COLOR) for s in out["cam_front"]]
    assert all(s.payload.format == "jpeg" and s.payload.frame_id == "cam_front" for s in out["cam_front"])
    assert all(f is not None and f.shape == (cam.settings.height, cam.settings.width, 3) for f in frames)
    assert len({s.payload.data for s in out["cam_front"]}) == len(frames)  # noise and the clock label


def test_truth_log_file(tmp_path):
    ctx = DeviceContext(clock=SessionClock(), rig_dir=tmp_path)
    glove = SimGlove("right", GloveSettings(truth_log="truth/sync.csv"), ctx)
    suit = SimSuit("body", SuitSettings(truth_log="truth/sync.csv"), ctx)
    out = run_together({"right": glove, "body": suit}, 0.4)
    ctx.shared["sim.truth"].flush()
    rows = list(csv.DictReader((tmp_path / "truth" / "sync.csv").open()))
    assert len(rows) == len(out["right"]) + len(out["body"])
    by_key = {(r["topic"], int(r["stamp_ns"])): int(r["true_ns"]) for r in rows}
    for s in out["right"] + out["body"]:
        assert abs(s.payload.stamp_ns - by_key[(s.topic, s.payload.stamp_ns)]) < 1_000_000
    with pytest.raises(ConfigError, match="one truth_log"):
        SimGlove("left", GloveSettings(truth_log="other.csv"), ctx)


def test_the_session_sets_the_operators_task_at_episode_start():
    ctx = DeviceContext(clock=SessionClock())
    glove = SimGlove("glove", GloveSettings(), ctx)
    SimSuit("suit", SuitSettings(), ctx)
    assert len(ctx.task_listeners) == 1  # one operator, registered once
    for listener in ctx.task_listeners:
        listener("wipe_table")  # not one of the five: the operator carries on
    assert glove.operator.task == "pick_place"
    for listener in ctx.task_listeners:
        listener("pour")
    t = glove.operator.time_s(ctx.clock.now_ns())
    assert "pour" in {glove.operator.episode(t + dt)[1] for dt in np.arange(0.0, 8.0, 0.1)}


def test_glove_and_suit_must_agree_on_the_operator():
    ctx = DeviceContext(clock=SessionClock())
    SimGlove("glove", GloveSettings(seed=1), ctx)
    with pytest.raises(ConfigError, match=r"\[devices.suit\].*same seed and task"):
        SimSuit("suit", SuitSettings(seed=2), ctx)


def test_read_before_connect_is_a_device_error():
    glove = SimGlove("glove", GloveSettings(), DeviceContext(clock=SessionClock()))
    with pytest.raises(DeviceError, match="not connected"):
        glove.read(0.01)
    glove.disconnect()
    glove.disconnect()  # twice is fine


def test_read_does_not_spin():
    glove = SimGlove("glove", GloveSettings(rate_hz=10.0), DeviceContext(clock=SessionClock()))
    glove.connect()
    cpu = time.thread_time()
    t0 = time.monotonic()
    n = 0
    while time.monotonic() - t0 < 0.5:
        n += len(glove.read(0.2))
    glove.disconnect()
    assert 3 <= n <= 7
    assert time.thread_time() - cpu < 0.05
