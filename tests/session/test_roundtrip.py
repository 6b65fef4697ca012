"""Session files written by McapSessionWriter read back by SessionReader: every payload type, bit-exact."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from teleprev import __version__
from teleprev import topics as T
from teleprev.errors import SessionError
from teleprev.messages import Event, ImageSample, JointSample, Logged, PoseSample, Transform, TransformsSample
from teleprev.session.codec import JointStatesDecoder, encode
from teleprev.session.reader import SessionReader
from teleprev.session.writer import McapSessionWriter

T0 = 1_700_000_000_123_456_789
HAND = tuple(f"{j}{i}.{c}" for j in ("index", "thumb") for i in (1, 2) for c in "xyz")


def same_payload(a, b) -> bool:
    """Equal, with float arrays compared bit for bit (NaN, -0.0 included)."""
    if type(a) is not type(b) or a.stamp_ns != b.stamp_ns:
        return False
    if isinstance(a, JointSample):
        if a.names != b.names or a.positions.tobytes() != np.asarray(b.positions, np.float64).tobytes():
            return False
        if a.velocities is None or b.velocities is None:
            return a.velocities is None and b.velocities is None
        return a.velocities.tobytes() == np.asarray(b.velocities, np.float64).tobytes()
    if isinstance(a, PoseSample):
        return (a.frame_id == b.frame_id and a.position.tobytes() == b.position.tobytes()
                and a.orientation.tobytes() == b.orientation.tobytes())
    if isinstance(a, TransformsSample):
        return len(a.transforms) == len(b.transforms) and all(
            x.parent == y.parent and x.child == y.child and x.translation.tobytes() == y.translation.tobytes()
            and x.rotation.tobytes() == y.rotation.tobytes() for x, y in zip(a.transforms, b.transforms))
    return a == b  # ImageSample, Event


def mixed_messages(rng, seconds: float = 2.0) -> list[Logged]:
    """Every payload type at its own rate, in log time order (log time = stamp + 0.5 ms)."""
    out = []
    specials = np.array([-0.0, 0.0, np.nan, np.inf, -np.inf, 5e-324, 1.7976931348623157e308, -1e-300])
    for k in range(int(120 * seconds)):
        t = T0 + k * 8_333_333
        pos = rng.standard_normal(len(HAND))
        if k < len(specials):
            pos[: k + 1] = specials[: k + 1]
        out.append(Logged("/glove/right/hand", t + 500_000, JointSample(t, HAND, pos)))
        if k % 2 == 0:
            arm = ("joint1", "joint2", "joint3")
            out.append(Logged("/arm/xarm/state", t + 500_000,
                              JointSample(t, arm, rng.uniform(-3, 3, 3), rng.uniform(-1, 1, 3))))
        if k % 4 == 0:
            out.append(Logged("/suit/s/wrist", t + 500_000, PoseSample(
                t, "world", rng.standard_normal(3), rng.standard_normal(4))))
            out.append(Logged(T.TF, t + 500_000, TransformsSample(t, tuple(
                Transform("link_base", f"link{i}", rng.standard_normal(3), rng.standard_normal(4)) for i in range(4)))))
            out.append(Logged(T.STEP_REPORT, t + 500_000, Event(t, "teleprev.StepReport", {
                "step": k, "corrector": "ccn", "colliding_links": ["a", "b"], "deviation_rad": float(rng.random()),
                "latency_us": 812.25, "ik_converged": True, "flags": []})))
        if k % 4 == 1:
            out.append(Logged("/camera/front/image", t + 500_000, ImageSample(t, "front", rng.bytes(2000), "jpeg")))
    out.append(Logged(T.EPISODE, T0 + 600_000, Event(T0 + 100_000, "teleprev.EpisodeEvent",
                                                     {"event": "start", "episode": 0, "task": "pour"})))
    out.sort(key=lambda m: m.log_time_ns)
    return out


def write_session(path, messages, metadata=None, flush_every: int = 0):
    with McapSessionWriter(path, metadata or {}) as w:
        for i, m in enumerate(messages):
            w.write(m)
            if flush_every and i % flush_every == flush_every - 1:
                w.flush()


@pytest.fixture
def session(tmp_path, rng):
    msgs = mixed_messages(rng)
    meta = {"rig": {"name": "sim", "glove": "sim.glove"}, "session": {"operator": "ann", "task": "pour"}}
    path = tmp_path / "s.mcap"
    write_session(path, msgs, meta, flush_every=97)
    return path, msgs, meta


def test_every_payload_round_trips_bit_exact(session):
    path, sent, _ = session
    with SessionReader(path) as reader:
        got = list(reader.messages())
    assert len(got) == len(sent)
    for a, b in zip(got, sent):
        assert (a.topic, a.log_time_ns) == (b.topic, b.log_time_ns)
        assert same_payload(a.payload, b.payload), (a, b)
    glove = [m.payload for m in got if m.topic == "/glove/right/hand"]
    assert isinstance(glove[0].names, tuple) and glove[0].positions.dtype == np.float64
    assert math.copysign(1.0, glove[0].positions[0]) == -1.0  # -0.0 kept
    assert glove[3].positions[3] == np.inf and np.isnan(glove[2].positions[2])


def test_topics_counts_times_and_metadata(session):
    path, sent, meta = session
    with SessionReader(path) as reader:
        topics = reader.topics
        assert set(topics) == {m.topic for m in sent}
        for name, info in topics.items():
            times = [m.log_time_ns for m in sent if m.topic == name]
            assert info.message_count == len(times)
            assert (info.first_ns, info.last_ns) == (min(times), max(times))
        assert topics["/glove/right/hand"].schema == "foxglove.JointStates"
        assert topics["/camera/front/image"].schema == "foxglove.CompressedImage"
        assert topics[T.TF].schema == "foxglove.FrameTransforms"
        assert topics["/suit/s/wrist"].schema == "foxglove.PoseInFrame"
        assert topics[T.STEP_REPORT].schema == "teleprev.StepReport"
        assert reader.metadata["rig"] == meta["rig"] and reader.metadata["session"] == meta["session"]
        tp = reader.metadata["teleprev"]
        assert tp["format_version"] == str(T.FORMAT_VERSION) and tp["software_version"] == __version__
        times = [m.log_time_ns for m in reader.messages()]
        assert times == sorted(times)
        assert reader.start_ns == sent[0].log_time_ns and reader.end_ns == sent[-1].log_time_ns


def test_file_is_a_standard_mcap_with_foxglove_schemas(session):
    """The mcap library reads it; event channels carry the titled JSON schema from topics.py."""
    from mcap.reader import make_reader

    path, sent, _ = session
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        by_topic = {c.topic: c for c in summary.channels.values()}
        schema = summary.schemas[by_topic[T.STEP_REPORT].schema_id]
        assert schema.encoding == "jsonschema" and json.loads(schema.data) == T.EVENT_SCHEMAS["teleprev.StepReport"]
        assert by_topic[T.STEP_REPORT].message_encoding == "json"
        assert summary.schemas[by_topic["/glove/right/hand"].schema_id].encoding == "protobuf"
        assert summary.statistics.message_count == len(sent)
        assert all(c.compression == "zstd" for c in summary.chunk_indexes) and len(summary.chunk_indexes) > 3
        n = sum(1 for _ in reader.iter_messages(log_time_order=False))
    assert n == len(sent)


def test_messages_filters_by_topic_and_time(session):
    path, sent, _ = session
    lo, hi = sent[100].log_time_ns, sent[300].log_time_ns
    with SessionReader(path) as reader:
        got = [(m.topic, m.log_time_ns) for m in reader.messages(["/arm/xarm/state", T.TF], lo, hi)]
        with pytest.raises(SessionError, match="no topic '/nope'"):
            list(reader.messages(["/nope"]))
    want = [(m.topic, m.log_time_ns) for m in sent if m.topic in ("/arm/xarm/state", T.TF) and lo <= m.log_time_ns < hi]
    assert got == want and got


def test_equal_and_out_of_order_log_times_come_out_sorted_and_stable(tmp_path):
    names = ("a",)
    msgs = [Logged("/x", t, JointSample(t, names, np.array([float(i)]))) for i, t in enumerate([5, 3, 3, 9, 1, 3])]
    path = tmp_path / "o.mcap"
    write_session(path, msgs)
    with SessionReader(path) as reader:
        got = [(m.log_time_ns, m.payload.positions[0]) for m in reader.messages()]
        assert list(reader.log_times("/x")) == [5, 3, 3, 9, 1, 3]  # file order, for `info`
    assert got == [(1, 4.0), (3, 1.0), (3, 2.0), (3, 5.0), (5, 0.0), (9, 3.0)]


def test_joint_layout_changes_decode_exactly(tmp_path, rng):
    """Names, joint count, velocities and timestamp widths changing within one topic: the per-layout
    fast path never returns something the full parse would not."""
    msgs = []
    for k in range(400):
        n = 3 + (k // 50) % 4
        names = tuple(f"j{i}" if k % 100 < 70 else f"other{i}" for i in range(n))
        vel = rng.standard_normal(n) if k % 3 == 0 else None
        stamp = [0, 5, 127, 128, 10**9 - 1, 10**9, T0][k % 7] + k
        msgs.append(Logged("/j", 1000 + k, JointSample(stamp, names, rng.standard_normal(n), vel)))
    path = tmp_path / "j.mcap"
    write_session(path, msgs, flush_every=37)
    with SessionReader(path) as reader:
        got = list(reader.messages())
    assert all(same_payload(a.payload, b.payload) for a, b in zip(got, msgs)) and len(got) == len(msgs)


def test_joint_decoder_agrees_with_protobuf_runtime(rng):
    """The hand-written JointStates decoder against the protobuf runtime built from the schema."""
    import foxglove.messages as fm

    from teleprev.session.codec import _protobuf_class

    cls = _protobuf_class("foxglove.JointStates", fm.JointStates.get_schema().data)
    dec = JointStatesDecoder()
    for k in range(50):
        names = HAND[: 1 + k % len(HAND)]
        sample = JointSample(T0 + k * 999_999_937, names, rng.standard_normal(len(names)),
                             rng.standard_normal(len(names)) if k % 2 else None)
        data = encode(sample)
        ref = cls.FromString(data)
        for got in (dec(data), dec.batch([data] * 5)[4]):
            assert got.stamp_ns == ref.timestamp.seconds * 10**9 + ref.timestamp.nanos == sample.stamp_ns
            assert got.names == tuple(j.name for j in ref.joints) == names
            assert got.positions.tolist() == [j.position for j in ref.joints]


def test_writer_rejects_bad_input_and_never_overwrites(tmp_path):
    path = tmp_path / "w.mcap"
    with McapSessionWriter(path, {}) as w:
        w.write(Logged("/a", 1, JointSample(1, ("x",), np.array([1.0]))))
        with pytest.raises(ValueError, match="topic /a carries foxglove.JointStates"):
            w.write(Logged("/a", 2, PoseSample(2, "w", np.zeros(3), np.array([0, 0, 0, 1.0]))))
        with pytest.raises(ValueError, match="unknown event schema 'teleprev.Nope'"):
            w.write(Logged("/e", 2, Event(2, "teleprev.Nope", {})))
        with pytest.raises(ValueError, match="positions has 2 values, expected 1"):
            w.write(Logged("/b", 2, JointSample(2, ("x",), np.array([1.0, 2.0]))))
        with pytest.raises(ValueError, match="reserved key"):
            w.write(Logged("/e", 2, Event(2, "teleprev.OperatorEvent", {"event": "x", "stamp_ns": 1})))
    with pytest.raises(SessionError, match="does not overwrite") as exc:
        McapSessionWriter(path, {})
    assert str(path) in str(exc.value)
    with pytest.raises(ValueError, match="key 'n' -> 3"):
        McapSessionWriter(tmp_path / "m.mcap", {"rig": {"n": 3}})
    with pytest.raises(ValueError, match="reserved"):
        McapSessionWriter(tmp_path / "m2.mcap", {"teleprev": {}})
    with SessionReader(path) as reader:  # what was written before the errors is intact
        assert [m.log_time_ns for m in reader.messages()] == [1]


def test_flushed_data_survives_an_unclosed_writer(tmp_path, rng):
    """After flush(), a copy of the file as it is on disk recovers every message written so far."""
    from teleprev.session.recover import recover

    msgs = mixed_messages(rng, seconds=0.5)
    path = tmp_path / "open.mcap"
    w = McapSessionWriter(path, {"session": {"task": "t"}})
    for m in msgs:
        w.write(m)
    w.flush()
    snapshot = tmp_path / "snapshot.mcap"
    snapshot.write_bytes(path.read_bytes())
    w.close()
    with pytest.raises(SessionError, match="teleprev recover"):
        SessionReader(snapshot)
    result = recover(snapshot)
    assert result.total == len(msgs) and result.salvaged == 0
    with SessionReader(result.dst) as reader:
        got = list(reader.messages())
        assert reader.metadata["session"] == {"task": "t"}
    assert all(same_payload(a.payload, b.payload) for a, b in zip(got, msgs)) and len(got) == len(msgs)


def test_joint_decoder_on_messages_other_writers_produce(rng):
    """Joint states written by another tool (extra fields, a missing position, no timestamp, joints
    before the timestamp): the full parse handles them and the fast path never claims them."""
    import foxglove.messages as fm

    from teleprev.session.codec import _protobuf_class

    cls = _protobuf_class("foxglove.JointStates", fm.JointStates.get_schema().data)
    dec = JointStatesDecoder()
    datas, want = [], []
    for k in range(40):
        m = cls()
        if k % 5:
            m.timestamp.seconds, m.timestamp.nanos = 1_700_000_000 + k, 1000 * k
        for i in range(4):
            j = m.joints.add(name=f"j{i}")
            if not (k % 4 == 1 and i == 2):
                j.position = float(rng.standard_normal())
            if k % 3 == 0:
                j.effort = 1.5
        data = m.SerializeToString()
        if k % 7 == 0:  # joints first, timestamp last: still valid protobuf
            data = data[data.index(b"\x12"):] + data[: data.index(b"\x12")] if data[0] == 0x0A else data
        datas.append(data)
        want.append((m.timestamp.seconds * 10**9 + m.timestamp.nanos,
                     [j.position if j.HasField("position") else None for j in m.joints]))
    for got in ([dec(d) for d in datas], dec.batch(datas * 2)[len(datas):]):
        for sample, (stamp, values) in zip(got, want):
            assert sample.stamp_ns == stamp and sample.names == ("j0", "j1", "j2", "j3")
            assert [None if np.isnan(v) else v for v in sample.positions.tolist()] == values
