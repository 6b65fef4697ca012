"""foxglove.PoseInFrame's batch decode (a learned byte layout, messages gathered as rows) gives exactly
what the protobuf runtime gives, message by message, whatever the layouts in the batch."""

from __future__ import annotations

from pathlib import Path

import foxglove.messages as fm
import numpy as np

from teleprev.messages import PoseSample
from teleprev.session.codec import (
    _POSE_TAIL_BYTES,
    POSE_IN_FRAME,
    PoseInFrameDecoder,
    _parse_pose_in_frame,
    _PoseLayout,
    _protobuf_class,
    _stamp,
    decoder_for,
    encode,
)

T0 = 1_700_000_000_123_456_789
FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_v3.mcap"
FILLER = np.frombuffer(b"\x3f" * 8, "<f8")[0]


def protobuf_decoder():
    """The protobuf runtime's decode, built from the schema as a file stores it: the reference."""
    cls = _protobuf_class(POSE_IN_FRAME, fm.PoseInFrame.get_schema().data)

    def decode(data: bytes) -> PoseSample:
        m = cls.FromString(data)
        p, q = m.pose.position, m.pose.orientation
        return PoseSample(_stamp(m.timestamp), m.frame_id, np.array((p.x, p.y, p.z)), np.array((q.x, q.y, q.z, q.w)))

    return decode


def same(a: PoseSample, b: PoseSample) -> bool:
    return (a.stamp_ns == b.stamp_ns and a.frame_id == b.frame_id and a.position.tobytes() == b.position.tobytes()
            and a.orientation.tobytes() == b.orientation.tobytes())


def test_batches_decode_as_the_protobuf_runtime(rng):
    samples = []
    for k in range(300):
        position, orientation = rng.standard_normal(3), rng.standard_normal(4)
        if k % 17 == 3:
            position[k % 3] = 0.0  # left out by the encoder: another length
        if k % 23 == 5:
            orientation[k % 4] = -0.0
        stamp = [T0 + k * 16_666_667, k, 0, 10**9, 127 * 10**9 + 128][0 if k % 11 else (k // 11) % 5]
        frame = "world" if k % 29 else ["", "w0rld", "a-much-longer-frame-name"][k % 3]
        samples.append(PoseSample(stamp, frame, position, orientation))
    datas = [encode(s) for s in samples]
    reference = protobuf_decoder()
    expected = [reference(d) for d in datas]
    # the messages that are not the common layout: a left-out double, an odd stamp, another frame id
    odd = [k % 17 == 3 or k % 23 == 5 or (k % 11 == 0 and (k // 11) % 5 != 0) or k % 29 == 0 for k in range(300)]
    decoded = []  # the messages that went through the protobuf runtime

    def counting(data):
        decoded.append(datas.index(data))
        return reference(data)

    fast = PoseInFrameDecoder(counting)
    fast(datas[0])  # learns the common layout
    assert fast._layouts
    for block in (datas[:7], datas[7:120], datas[120:]):
        first = datas.index(block[0])
        decoded.clear()
        got = fast.batch(block)
        assert all(same(a, b) for a, b in zip(got, expected[first:]))
        assert len(got) == len(block)
        if len(block) > 100:  # (a small block's few rows of a length are decoded one by one)
            # rows of a known layout are read from the array; only the others, and the first of a common
            # length not learned yet (the nanoseconds varint grows a byte), go through protobuf
            assert len(decoded) <= sum(odd[first:first + len(block)]) + 2 < len(block) // 4
    decoded.clear()
    assert all(same(a, b) for a, b in zip(fast.batch(datas), expected))
    assert len(decoded) <= sum(odd) < len(datas) // 4


def test_a_layout_is_learned_only_when_it_reads_back_the_message():
    d = PoseInFrameDecoder(protobuf_decoder())
    d(encode(PoseSample(T0, "world", np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))))  # zeros: not the plain layout
    assert not d._layouts
    d(encode(PoseSample(T0, "world", np.ones(3), np.ones(4))))
    assert len(d._layouts) == 1


def test_a_layout_whose_tail_matches_but_reads_the_message_differently_is_not_kept():
    # A message with no pose whose frame id is the byte tail of a pose whose doubles are all 0x3f3f...
    # (ASCII, so valid UTF-8): its last bytes match the plain layout's fixed tail, but protobuf reads a
    # frame id and a zero pose, not those doubles; only the read-back check tells them apart.
    pose_tail = encode(PoseSample(T0, "world", np.full(3, FILLER), np.full(4, FILLER)))[-_POSE_TAIL_BYTES:]
    cls = _protobuf_class(POSE_IN_FRAME, fm.PoseInFrame.get_schema().data)
    m = cls(frame_id=pose_tail.decode("utf-8"))
    m.timestamp.seconds, m.timestamp.nanos = divmod(T0, 10**9)
    data = m.SerializeToString()
    assert data.endswith(pose_tail)
    sample = protobuf_decoder()(data)
    assert sample.frame_id == pose_tail.decode("utf-8") and not sample.position.any()
    assert _PoseLayout.learn(data, sample) is None
    d = PoseInFrameDecoder(protobuf_decoder())
    assert same(d(data), sample)
    assert not d._layouts
    assert all(same(got, sample) for got in d.batch([data] * 10))
    assert not d._layouts


def test_messages_that_cannot_be_learned_are_not_learned_again_and_again(monkeypatch):
    calls = []
    learn = _PoseLayout.learn.__func__

    def counting_learn(cls, data, sample):
        calls.append(len(data))
        return learn(cls, data, sample)

    monkeypatch.setattr(_PoseLayout, "learn", classmethod(counting_learn))
    # planar poses: z is exactly 0.0, which the encoder leaves out, so no message has the plain layout
    datas = [encode(PoseSample(T0 + k * 8_333_333, "world", np.array([1.0 + k, 2.0, 0.0]), np.ones(4)))
             for k in range(2000)]
    d = PoseInFrameDecoder(protobuf_decoder())
    expected = [protobuf_decoder()(x) for x in datas]
    for block in (datas[:500], datas[500:]):
        assert all(same(a, b) for a, b in zip(d.batch(block), expected[datas.index(block[0]):]))
    assert not d._layouts
    assert len(calls) <= PoseInFrameDecoder._MAX_FAILED_LEARNS
    # a learnable message afterwards still gets its layout
    d(encode(PoseSample(T0, "world", np.ones(3), np.ones(4))))
    assert len(d._layouts) == 1


def _field(number: int, payload: bytes) -> bytes:
    """A length-delimited protobuf field (numbers and lengths under 128 here)."""
    return bytes((number << 3 | 2, len(payload))) + payload


def _double(number: int, value: float) -> bytes:
    return bytes((number << 3 | 1,)) + np.float64(value).tobytes()


def _varint_field(number: int, value: int) -> bytes:
    out = bytearray((number << 3,))
    value &= (1 << 64) - 1
    while value >= 0x80:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _random_message(rng) -> bytes:
    """PoseInFrame bytes as any writer may lay them out: fields in any order, some left out, some
    repeated (a pose merged into the one before), unknown fields of each wire type between them."""
    def unknown() -> bytes:
        return [_varint_field(9, int(rng.integers(0, 1 << 40))), _double(10, rng.standard_normal()),
                _field(11, b"xyz"), bytes((12 << 3 | 5,)) + b"\x01\x02\x03\x04"][int(rng.integers(4))]

    def some(parts: list[bytes]) -> bytes:
        kept = [p for p in parts if rng.random() < 0.8]
        if rng.random() < 0.3:
            kept.insert(int(rng.integers(len(kept) + 1)), unknown())
        order = rng.permutation(len(kept))
        return b"".join(kept[i] for i in order)

    def pose() -> bytes:
        position = some([_double(i + 1, rng.standard_normal()) for i in range(3)])
        orientation = some([_double(i + 1, rng.standard_normal()) for i in range(4)])
        return _field(3, some([_field(1, position), _field(2, orientation)]))

    stamp = _field(1, some([_varint_field(1, int(rng.integers(-5, 2_000_000_000))),
                            _varint_field(2, int(rng.integers(-5, 10**9)))]))
    parts = [stamp, _field(2, ["world", "", "wrist_l", "ü"][int(rng.integers(4))].encode()), pose()]
    if rng.random() < 0.3:
        parts.append(pose())
    if rng.random() < 0.2:
        parts.append(_field(2, b"again"))
    return some(parts)


def test_the_full_parse_reads_what_the_protobuf_runtime_reads(rng):
    reference = protobuf_decoder()
    for _ in range(3000):
        data = _random_message(rng)
        assert same(_parse_pose_in_frame(data), reference(data)), data.hex()


def test_the_full_parse_refuses_what_the_protobuf_runtime_refuses(rng):
    from google.protobuf.message import DecodeError

    reference = protobuf_decoder()
    for _ in range(300):
        data = _random_message(rng)
        for cut in range(len(data)):
            try:
                expected = reference(data[:cut])
            except DecodeError:
                expected = None
            try:
                got = _parse_pose_in_frame(data[:cut])
            except (ValueError, IndexError):  # what the reader reports as a message that does not decode
                got = None
            assert (got is None) == (expected is None), (data.hex(), cut)
            assert got is None or same(got, expected)


def test_reading_poses_does_not_load_the_protobuf_runtime(tmp_path):
    """The runtime's import takes ~40 ms, a tenth of a short session's eval: eval's streams do without."""
    import subprocess
    import sys

    code = (
        "import sys\nfrom teleprev.session.reader import SessionReader\n"
        f"with SessionReader({str(FIXTURE)!r}) as r:\n"
        "    poses = [m for m in r.messages(topics=[t for t, s in r.schemas.items() if s == 'foxglove.PoseInFrame'])]\n"
        "assert poses, 'no poses'\n"
        "print(len(poses), 'google.protobuf' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert int(out[0]) > 100 and out[1] == "False"


def test_decoder_for_reads_poses_with_the_full_parse():
    decoder = decoder_for(POSE_IN_FRAME, "protobuf", fm.PoseInFrame.get_schema().data, "protobuf")
    assert decoder._decode is _parse_pose_in_frame  # not the runtime's, which reads the same
    sample = PoseSample(T0, "world", np.array([0.5, -0.25, 0.0]), np.array([0.0, 0.0, 0.6, 0.8]))
    assert same(decoder(encode(sample)), protobuf_decoder()(encode(sample)))
