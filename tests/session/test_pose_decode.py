"""foxglove.PoseInFrame's batch decode (a learned byte layout, messages gathered as rows) gives exactly
what the protobuf runtime gives, message by message, whatever the layouts in the batch."""

from __future__ import annotations

import foxglove.messages as fm
import numpy as np

from teleprev.messages import PoseSample
from teleprev.session.codec import (_POSE_TAIL_BYTES, POSE_IN_FRAME, PoseInFrameDecoder, _pose_decoder, _PoseLayout,
                                   _protobuf_class, encode)

T0 = 1_700_000_000_123_456_789
FILLER = np.frombuffer(b"\x3f" * 8, "<f8")[0]


def protobuf_decoder():
    return _pose_decoder(_protobuf_class(POSE_IN_FRAME, fm.PoseInFrame.get_schema().data))


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
