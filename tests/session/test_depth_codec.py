"""Depth and camera calibration in session files: written by McapSessionWriter, read back by SessionReader
bit-exact, in both storage forms, with the unit carried by the channel; what Foxglove needs to draw it."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from teleprev.messages import CameraInfo, DepthSample, ImageSample, Logged
from teleprev.session.codec import DEPTH_SCALE_KEY, decoder_for
from teleprev.session.reader import SessionReader
from teleprev.session.writer import McapSessionWriter

T0 = 1_700_000_000_000_000_000


def depth_image(seed: int, h: int = 48, w: int = 64) -> np.ndarray:
    rng = np.random.default_rng(seed)
    d = rng.integers(0, 65536, (h, w), dtype=np.uint16)
    d[0, :3] = (0, 1, 65535)  # the extremes survive
    return d


@pytest.mark.parametrize("form, schema", [("raw", "foxglove.RawImage"), ("png", "foxglove.CompressedImage")])
def test_depth_round_trips_bit_exact_with_its_scale(tmp_path, form, schema):
    path = tmp_path / "s.mcap"
    sent = [DepthSample(T0 + i * 33_000_000, "wrist", depth_image(i), 0.0001, form) for i in range(5)]
    info = CameraInfo(T0, "wrist", 64, 48, (60.0, 0.0, 32.0, 0.0, 61.0, 24.0, 0.0, 0.0, 1.0), (0.1, -0.2, 0, 0, 0.01))
    colour = ImageSample(T0, "wrist", b"\x89PNG not really", "png")
    with McapSessionWriter(path) as w:
        w.write(Logged("/camera/wrist/calibration", T0, info))
        w.write(Logged("/camera/wrist/image", T0, colour))
        for s in sent:
            w.write(Logged("/camera/wrist/depth", s.stamp_ns, s))
    with SessionReader(path) as r:
        assert r.schemas["/camera/wrist/depth"] == schema
        got = [m.payload for m in r.messages(["/camera/wrist/depth"])]
        (back_info,) = [m.payload for m in r.messages(["/camera/wrist/calibration"])]
        (back_colour,) = [m.payload for m in r.messages(["/camera/wrist/image"])]
    assert [type(g) for g in got] == [DepthSample] * 5
    for a, b in zip(sent, got):
        assert (b.stamp_ns, b.frame_id, b.scale_m, b.format) == (a.stamp_ns, "wrist", 0.0001, form)
        assert b.depth.dtype == np.uint16 and np.array_equal(a.depth, b.depth)
    assert got[0].metres()[0, 2] == pytest.approx(65535 * 0.0001, rel=1e-6)
    assert back_info == info
    assert back_colour == colour  # a colour PNG on a channel without a depth unit stays an ImageSample


def test_foxglove_reads_the_depth_channel_as_16uc1_with_the_unit_in_its_metadata(tmp_path):
    """What Foxglove's 3D panel reads: a RawImage 16UC1 and a CameraCalibration on the same frame_id."""
    path = tmp_path / "s.mcap"
    with McapSessionWriter(path) as w:
        w.write(Logged("/camera/c/depth", T0, DepthSample(T0, "c", depth_image(0), 0.001)))
    from foxglove.messages import RawImage  # noqa: F401 (the schema Foxglove knows)
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    with open(path, "rb") as f:
        ((schema, channel, message),) = list(make_reader(f).iter_messages())
    assert channel.metadata == {DEPTH_SCALE_KEY: "0.001"}
    fds = descriptor_pb2.FileDescriptorSet.FromString(schema.data)
    pool = descriptor_pool.DescriptorPool()
    for fd in fds.file:
        pool.Add(fd)
    m = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name)).FromString(message.data)
    assert (m.encoding, m.width, m.height, m.step, len(m.data)) == ("16UC1", 64, 48, 128, 64 * 48 * 2)


def test_a_depth_topic_refuses_another_unit_or_form(tmp_path):
    with McapSessionWriter(tmp_path / "s.mcap") as w:
        w.write(Logged("/camera/c/depth", T0, DepthSample(T0, "c", depth_image(0), 0.001)))
        with pytest.raises(ValueError, match="depth_scale_m"):
            w.write(Logged("/camera/c/depth", T0 + 1, DepthSample(T0 + 1, "c", depth_image(1), 0.0001)))
        with pytest.raises(ValueError, match="CompressedImage"):
            w.write(Logged("/camera/c/depth", T0 + 1, DepthSample(T0 + 1, "c", depth_image(1), 0.001, "png")))


def test_bad_depth_is_refused_with_what_is_wrong(tmp_path):
    with McapSessionWriter(tmp_path / "s.mcap") as w:
        with pytest.raises(ValueError, match="uint16"):
            w.write(Logged("/camera/c/depth", T0, DepthSample(T0, "c", np.zeros((4, 4), np.float32), 0.001)))
    with pytest.raises(ValueError, match="not a positive number"):
        decoder_for("foxglove.RawImage", "protobuf", b"", "protobuf", {DEPTH_SCALE_KEY: "mm"})


def test_a_writer_behind_sheds_depth_frames_first_as_camera_frames(tmp_path):
    """Depth is the largest camera stream: a writer past its lag budget sheds it with the colour frames."""
    import time

    from teleprev.messages import JointSample
    from teleprev.session.recorder import Recorder

    rec = Recorder(tmp_path / "s.mcap", lag_budget_s=0.2)
    depth = Logged("/camera/c/depth", T0, DepthSample(T0, "c", depth_image(0), 0.001))
    assert rec.log(depth)  # on time: taken
    time.sleep(0.25)  # the writer has not run: the oldest queued message is past the budget
    assert not rec.log(Logged("/camera/c/depth", T0 + 1, DepthSample(T0 + 1, "c", depth_image(1), 0.001)))
    assert rec.log(Logged("/arm/a/state", T0 + 2, JointSample(T0 + 2, ("j",), np.array([0.1]))))
    summary = rec.start().close()
    assert summary.streams["/camera/c/depth"].shed == 1 and summary.streams["/camera/c/depth"].written == 1
