"""realsense.camera through the real librealsense: a camera made of the SDK's software_device
(teleprev_devices.realsense_software), opened, streamed, aligned and lost by the plugin exactly as a USB one."""

from __future__ import annotations

import numpy as np
import pytest

from teleprev.devices import (
    CameraInfo,
    DepthSample,
    DeviceContext,
    DeviceError,
    DeviceRunner,
    ImageSample,
    SessionClock,
    TransformsSample,
)
from teleprev_devices.realsense import RealSenseCamera, RealSenseSettings
from teleprev_devices.realsense_software import SoftwareRealSense
from tests.helpers.wait import wait_until

W, H = 160, 120  # small frames: the tests are about the path, bench/depth.py about 640x480 at 30 fps


def camera(name="wrist", **settings) -> RealSenseCamera:
    return RealSenseCamera(name, RealSenseSettings(width=W, height=H, **settings), DeviceContext(SessionClock()))


class Recording:
    """A camera run by the session's DeviceRunner; what it delivered."""

    def __init__(self, device: RealSenseCamera, **runner):
        self.device, self.samples = device, []
        self.runner = DeviceRunner(device, lambda sample, receive_ns: self.samples.append((sample, receive_ns)),
                                   device.context.clock, **runner).start()

    def of(self, kind):
        return [s.payload for s, _ in self.samples if isinstance(s.payload, kind)]

    def events(self, event: str) -> list[str]:
        return [s.payload.data["message"] for s, _ in self.samples
                if s.topic == "/events/device" and s.payload.data["event"] == event]

    def stop(self):
        self.runner.stop()


@pytest.fixture
def d405():
    with SoftwareRealSense(serial="000000000405", model="D405", width=W, height=H) as cam:
        yield cam


@pytest.fixture
def d435():
    with SoftwareRealSense(serial="000000000435", model="D435", width=W, height=H, clock_origin_ms=9e6) as cam:
        yield cam


def test_depth_and_colour_arrive_paired_in_the_cameras_unit_with_hardware_time(d405):
    rec = Recording(camera(serial="000000000405", align_depth=False))
    wait_until(lambda: len(rec.of(DepthSample)) >= 20, 10, what="20 depth frames")
    rec.stop()
    depths, colours = rec.of(DepthSample), rec.of(ImageSample)
    assert rec.runner.stats().errors == 0 and rec.device.counters()["unpaired_frames"] == 0
    d = depths[0]
    assert (d.frame_id, d.depth.shape, d.depth.dtype, d.format) == ("wrist_depth", (H, W), np.uint16, "raw")
    assert d.scale_m == pytest.approx(0.0001)  # get_depth_scale(): a D405 counts 0.1 mm, not 1 mm
    # every frame is one the camera was fed, counts exact
    numbers = [SoftwareRealSense.number_of(s.depth) for s in depths]
    assert all(np.array_equal(s.depth, d405.depth_for(n)) for s, n in zip(depths, numbers))
    assert numbers == sorted(numbers)
    # depth and colour of one frame share one session stamp (they share one hardware stamp)
    by_stamp = {c.stamp_ns for c in colours}
    assert all(s.stamp_ns in by_stamp for s in depths)
    # stamps are the hardware stamps moved by ClockSync's offset, which only ever improves (the fastest
    # delivery seen so far), so stamps keep the hardware's spacing to within that correction
    hardware_ns = {f.number: round(f.hardware_ms * 1e6) for f in d405.fed}
    offsets = np.array([s.stamp_ns - hardware_ns[n] for s, n in zip(depths, numbers)])
    assert np.all(np.diff(offsets) <= 0) and offsets[0] - offsets[-1] < 200_000_000
    # and they sit on the session clock: at most the delivery time before their receive time
    for sample, receive_ns in rec.samples:
        if isinstance(sample.payload, DepthSample):
            assert 0 <= receive_ns - sample.payload.stamp_ns < 500_000_000


def test_aligned_depth_takes_colours_frame_and_intrinsics_and_the_camera_is_on_tf(d435):
    rec = Recording(camera(serial="000000000435", parent_frame="link_base", mount_xyz=(0.1, 0.2, 0.3)))
    wait_until(lambda: len(rec.of(DepthSample)) >= 5 and rec.of(CameraInfo), 10, what="aligned depth")
    rec.stop()
    d = rec.of(DepthSample)[-1]
    assert d.frame_id == "wrist" and d.depth.shape == (H, W) and d.scale_m == pytest.approx(0.001)
    # the colour camera sits 15 mm beside the depth one: aligned depth is reprojected, not a copy
    assert not np.array_equal(d.depth, d435.depth_for(SoftwareRealSense.number_of(d.depth)))
    info = rec.of(CameraInfo)[0]
    assert (info.frame_id, info.width, info.height) == ("wrist", W, H)
    assert info.k == pytest.approx((0.6 * W, 0, W / 2 - 0.5, 0, 0.6 * W, H / 2 - 0.5, 0, 0, 1))
    (tf,) = rec.of(TransformsSample)[:1]
    (mount,) = tf.transforms
    assert (mount.parent, mount.child) == ("link_base", "wrist")
    assert mount.translation.tolist() == [0.1, 0.2, 0.3]


def test_unaligned_depth_has_its_own_frame_beside_colour_on_tf(d435):
    rec = Recording(camera(serial="000000000435", align_depth=False))
    wait_until(lambda: rec.of(TransformsSample) and rec.of(CameraInfo), 10, what="calibration")
    rec.stop()
    mount, depth_in_colour = rec.of(TransformsSample)[0].transforms
    assert (depth_in_colour.parent, depth_in_colour.child) == ("wrist", "wrist_depth")
    assert depth_in_colour.translation == pytest.approx([0.015, 0, 0])
    assert rec.of(CameraInfo)[0].frame_id == "wrist_depth"


def test_serial_picks_the_camera_and_a_missing_one_names_those_found(d405, d435):
    dev = camera(serial="000000000435")
    dev.connect()
    assert dev.depth_scale == pytest.approx(0.001)
    dev.disconnect()
    with pytest.raises(DeviceError, match=r"no RealSense camera with serial 999 .*found: 000000000405 \(Intel "
                                          r"RealSense D405.*000000000435 \(Intel RealSense D435"):
        camera(serial="999").connect()
    with pytest.raises(DeviceError, match="2 RealSense cameras are connected .*: set serial"):
        camera().connect()


def test_a_mode_the_camera_lacks_names_the_modes_it_has(d405):
    dev = RealSenseCamera("wrist", RealSenseSettings(serial="000000000405", width=1280, height=720),
                          DeviceContext(SessionClock()))
    with pytest.raises(DeviceError, match=r"no depth stream of 1280x720 at 30 fps; it offers 160x120@30"):
        dev.connect()


def test_frames_that_stop_are_a_gap_then_an_error_and_come_back(d405):
    rec = Recording(camera(serial="000000000405", stall_timeout_s=0.3), reconnect_s=0.2)
    wait_until(lambda: rec.of(DepthSample), 10, what="first frames")
    d405.pause()
    wait_until(lambda: rec.events("error"), 10, what="the stall reported")
    assert rec.events("gap") and "no frames for" in rec.events("error")[0]
    before = len(rec.of(DepthSample))
    d405.resume()
    wait_until(lambda: len(rec.of(DepthSample)) > before + 5, 10, what="frames again")
    rec.stop()
    assert rec.events("recovered")


def test_an_unplugged_camera_is_reported_missing_and_streams_again_when_replugged(d405):
    rec = Recording(camera(serial="000000000405", stall_timeout_s=0.3), reconnect_s=0.2)
    wait_until(lambda: rec.of(DepthSample), 10, what="first frames")
    d405.unplug()
    wait_until(lambda: any("no RealSense camera with serial 000000000405" in m for m in rec.events("error")), 10,
               what="the missing camera named")
    assert any("found: none" in m for m in rec.events("error"))
    before = len(rec.of(DepthSample))
    d405.replug()
    wait_until(lambda: len(rec.of(DepthSample)) > before + 5, 10, what="frames after replugging")
    rec.stop()
    assert rec.runner.stats().connects >= 2


@pytest.mark.parametrize("jump_ms", [5000.0, -5000.0])
def test_a_hardware_clock_jump_is_counted_and_stamps_stay_on_the_session_clock(d405, jump_ms):
    rec = Recording(camera(serial="000000000405"))
    wait_until(lambda: len(rec.of(DepthSample)) >= 5, 10, what="first frames")
    d405.jump_clock_ms(jump_ms)
    wait_until(lambda: rec.device.counters()["timestamp_jumps"] == 1, 10, what="the jump counted")
    n = len(rec.samples)
    wait_until(lambda: len(rec.samples) > n + 10 and rec.events("skipped"), 10, what="frames after the jump")
    rec.stop()
    assert "1 timestamp jumps" in rec.events("skipped")[0]
    for sample, receive_ns in rec.samples:  # no frame stamped seconds away from when it arrived
        if isinstance(sample.payload, DepthSample):
            assert abs(receive_ns - sample.payload.stamp_ns) < 500_000_000


def test_settings_are_checked():
    for bad, match in (({"depth_format": "jpeg"}, "depth_format"), ({"fps": 0}, "fps"),
                       ({"mount_quat": (0, 0, 0, 2)}, "unit quaternion"), ({"depth_width": 320}, "depth_width")):
        with pytest.raises(ValueError, match=match):
            RealSenseSettings(**bad)


def test_the_depth_unit_of_a_different_camera_is_refused(d405, d435):
    dev = camera(serial="000000000405")
    dev.connect()
    dev.disconnect()
    dev.settings.serial = "000000000435"
    with pytest.raises(DeviceError, match="a different camera was plugged in"):
        dev.connect()
