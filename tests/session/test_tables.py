"""SessionReader.messages(tables=...): JointStates topics gathered as tables (stamp and positions per
message) in the same pass as the messages it yields. A table must hold exactly what messages() would
have yielded on its topic, in the same order, and a damaged file must fail the same way."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from teleprev import topics as T
from teleprev.errors import SessionError
from teleprev.messages import JointSample, Logged, PoseSample
from teleprev.session.codec import JointStatesDecoder, encode, schema_for
from teleprev.session.reader import JointTable, SessionReader
from tests.helpers.faults import damage_chunk
from tests.session.test_roundtrip import same_payload, write_session

FIXTURE = Path(__file__).resolve().parents[1] / "fixtures" / "sim_v2.mcap"
STREAMED = ["/glove/glove/hand", "/suit/suit/wrist", "/arm/arm/state", "/hand/hand/state", T.MODE]
TABLED = [T.RETARGETED, T.CORRECTED, T.ARM_TARGET, T.COMMAND_ARM, T.COMMAND_HAND]


def read_plain(reader, streamed, tabled, lo=None, hi=None):
    """What messages() alone gives: the streamed messages, and per tabled topic (stamp, positions)."""
    got, tables, error = [], {t: [] for t in tabled}, None
    try:
        for m in reader.messages([*streamed, *tabled], lo, hi):
            if m.topic in tables:
                tables[m.topic].append((m.payload.stamp_ns, m.payload.positions))
            else:
                got.append(m)
    except SessionError as exc:
        error = str(exc)
    return got, tables, error


def read_tabled(reader, streamed, tabled, lo=None, hi=None):
    tables = {t: JointTable() for t in tabled}
    got, error = [], None
    try:
        for m in reader.messages(streamed, lo, hi, tables=tables):
            got.append(m)
    except SessionError as exc:
        error = str(exc)
    return got, {t: list(zip(tab.stamp_ns, tab.positions)) for t, tab in tables.items()}, error


def assert_same_reading(a, b):
    (got_a, tables_a, error_a), (got_b, tables_b, error_b) = a, b
    assert error_a == error_b
    assert len(got_a) == len(got_b)
    for x, y in zip(got_a, got_b):
        assert (x.topic, x.log_time_ns) == (y.topic, y.log_time_ns) and same_payload(x.payload, y.payload)
    assert tables_a.keys() == tables_b.keys()
    for topic in tables_a:
        assert len(tables_a[topic]) == len(tables_b[topic]), topic
        for (s, p), (s2, p2) in zip(tables_a[topic], tables_b[topic]):
            assert s == s2 and p.dtype == p2.dtype and p.tobytes() == p2.tobytes()


@pytest.mark.parametrize("window", [None, (1.0, 2.5)])
def test_tables_hold_what_messages_yields_on_a_recorded_session(window):
    with SessionReader(FIXTURE) as reader:
        lo = hi = None
        if window:
            lo, hi = (reader.start_ns + int(s * 1e9) for s in window)
        plain = read_plain(reader, STREAMED, TABLED, lo, hi)
        assert_same_reading(plain, read_tabled(reader, STREAMED, TABLED, lo, hi))
        assert plain[2] is None and all(len(v) > 10 for v in plain[1].values())


def test_a_table_with_nothing_streamed():
    with SessionReader(FIXTURE) as reader:
        got, tables, error = read_tabled(reader, [], TABLED)
        assert got == [] and error is None
        assert_same_reading(read_plain(reader, [], TABLED), (got, tables, error))


def test_tables_follow_log_time_order_across_overlapping_chunks(tmp_path):
    """Out-of-order log times over small chunks: chunks overlap in time and are merged, with equal log
    times kept in file order, in the tables as in the messages."""
    rng = np.random.default_rng(3)
    times = [50, 30, 30, 90, 10, 30, 70, 20, 20, 60, 40, 80, 10, 90]
    msgs = []
    for i, t in enumerate(times):
        msgs.append(Logged("/x", t, JointSample(1000 + i % 4, ("a", "b"), rng.standard_normal(2))))
        msgs.append(Logged("/y", t, JointSample(t, ("c",), rng.standard_normal(1))))
        msgs.append(Logged("/p", t, PoseSample(t, "w", rng.standard_normal(3), rng.standard_normal(4))))
    path = tmp_path / "o.mcap"
    write_session(path, msgs, flush_every=5)
    with SessionReader(path) as reader:
        chunks = sorted(reader._chunks, key=lambda c: c.offset)
        assert any(b.start_ns < a.end_ns for a, b in zip(chunks, chunks[1:]))  # the merging path runs
        plain = read_plain(reader, ["/y", "/p"], ["/x"])
        assert_same_reading(plain, read_tabled(reader, ["/y", "/p"], ["/x"]))
        assert_same_reading(read_plain(reader, ["/p"], ["/x", "/y"]), read_tabled(reader, ["/p"], ["/x", "/y"]))


def _write_raw(path, messages, *, message_index: bool):
    """An MCAP of (topic, log time, encoded bytes, payload for the schema) through the mcap writer itself,
    with or without message indexes (without them, the reader parses chunks record by record)."""
    from mcap.writer import CompressionType, IndexType, Writer

    index = IndexType.ALL if message_index else IndexType.CHUNK | IndexType.METADATA
    channels = {}
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1 << 12, compression=CompressionType.ZSTD, index_types=index)
        w.start()
        for topic, t, data, like in messages:
            if topic not in channels:
                spec = schema_for(like)
                channels[topic] = w.register_channel(topic, spec.message_encoding,
                                                     w.register_schema(spec.name, spec.encoding, spec.data))
            w.add_message(channels[topic], t, data, t)
        w.finish()


@pytest.mark.parametrize("message_index", [True, False])
def test_an_undecodable_message_fails_the_same_with_tables(tmp_path, message_index):
    """A message of the tabled topic that does not decode: the same error, naming it, after the same
    messages."""
    rng = np.random.default_rng(4)
    msgs = []
    for k in range(400):
        x = JointSample(k, ("a", "b", "c"), rng.standard_normal(3))
        data = encode(x) if k != 300 else encode(x)[:-3]  # cut short: does not decode
        msgs.append(("/x", 1000 + k, data, x))
        y = JointSample(k, ("d",), rng.standard_normal(1))
        msgs.append(("/y", 1000 + k, encode(y), y))
    path = tmp_path / "bad.mcap"
    _write_raw(path, msgs, message_index=message_index)
    with SessionReader(path, any_mcap=True) as reader:
        assert len(reader._chunks) > 8  # more than one batch of chunks, the bad one inside the second
        plain = read_plain(reader, ["/y"], ["/x"])
        assert plain[2] is not None and "message on /x at log time 1300 does not decode" in plain[2]
        # every message of the chunks before the one that fails, none after
        bad = next(c for c in reader._chunks if c.start_ns <= 1300 <= c.end_ns)
        assert [m.log_time_ns for m in plain[0]] == list(range(1000, bad.start_ns))
        assert_same_reading(plain, read_tabled(reader, ["/y"], ["/x"]))
        good_until = reader.start_ns + 100
        assert_same_reading(read_plain(reader, ["/y"], ["/x"], hi=good_until),
                            read_tabled(reader, ["/y"], ["/x"], hi=good_until))


def test_sequentially_parsed_chunks_give_the_same_tables(tmp_path):
    """No message indexes: the chunks are parsed record by record, with the same result."""
    with SessionReader(FIXTURE) as reader:
        messages = list(reader.messages([*STREAMED[:3], *TABLED]))
    path = tmp_path / "noindex.mcap"
    _write_raw(path, [(m.topic, m.log_time_ns, encode(m.payload), m.payload) for m in messages], message_index=False)
    with SessionReader(path, any_mcap=True) as reader:
        assert not any(c.message_index_offsets for c in reader._chunks)
        assert_same_reading(read_plain(reader, STREAMED[:3], TABLED), read_tabled(reader, STREAMED[:3], TABLED))


@pytest.mark.parametrize("which", ["first", "first of a batch", "inside a batch"])
def test_a_damaged_chunk_fails_the_same_with_tables(tmp_path, which):
    """The messages of every chunk before the damaged one come first, then its error."""
    path = tmp_path / "damaged.mcap"
    shutil.copy(FIXTURE, path)
    with SessionReader(path) as reader:
        n = len(reader._chunks)
    assert n > 10
    start, _ = damage_chunk(path, {"first": 0, "first of a batch": 8, "inside a batch": 10}[which])
    with SessionReader(path) as reader:
        plain = read_plain(reader, STREAMED, TABLED)
        assert plain[2] is not None and "is damaged" in plain[2]
        before = read_plain(reader, STREAMED, TABLED, hi=start)  # every message of the chunks before it
        assert before[2] is None
        assert_same_reading((*before[:2], plain[2]), plain)
        assert_same_reading(plain, read_tabled(reader, STREAMED, TABLED))


def test_only_joint_states_topics_make_tables():
    with SessionReader(FIXTURE) as reader, pytest.raises(SessionError, match="is not foxglove.JointStates"):
        list(reader.messages(["/glove/glove/hand"], tables={"/suit/suit/wrist": JointTable()}))


def test_columns_decode_what_batch_decodes(rng, monkeypatch):
    """JointStatesDecoder.columns against batch: a learned layout, messages of other layouts and lengths
    among them, and a message that only looks like the layout (its name differs)."""
    dec = JointStatesDecoder()
    names = ("j0", "j1", "j2")
    samples = [JointSample(10**9 * (k + 1) + 7, names, rng.standard_normal(3)) for k in range(12)]
    samples[5] = JointSample(10**9 * 6 + 7, ("k0", "j1", "j2"), rng.standard_normal(3))  # same length, other name
    samples[8] = JointSample(8, names[:2], rng.standard_normal(2))  # other length
    samples[9] = JointSample(9, names, rng.standard_normal(3), rng.standard_normal(3))  # velocities
    datas = [encode(s) for s in samples]
    dec(datas[0])  # learn the layout
    groups = [(idxs, layout is not None) for idxs, layout, _ in dec._by_layout(datas)]
    assert ([0, 1, 2, 3, 4, 5, 6, 7, 10, 11], True) in groups  # an array of rows, message 5 not matching
    one_by_one = []
    call = JointStatesDecoder.__call__

    def counting_call(self, data):
        one_by_one.append(datas.index(data))
        return call(self, data)

    monkeypatch.setattr(JointStatesDecoder, "__call__", counting_call)
    stamps, positions = dec.columns(datas)
    assert sorted(one_by_one) == [5, 8, 9]  # the rows of the layout are read from the array
    monkeypatch.undo()
    batch = JointStatesDecoder()
    batch(datas[0])
    expected = batch.batch(datas)
    assert stamps == [s.stamp_ns for s in expected] == [s.stamp_ns for s in samples]
    assert [p.tobytes() for p in positions] == [s.positions.tobytes() for s in expected]
    assert [p.tobytes() for p in positions] == [s.positions.tobytes() for s in samples]
