"""`recover`: a recorder killed with SIGKILL, files cut at any byte, zero-filled tails, a damaged chunk."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from teleprev.errors import SessionError
from teleprev.messages import JointSample, Logged
from teleprev.session.reader import SessionReader
from teleprev.session.recover import recover
from teleprev.session.writer import McapSessionWriter

ROOT = Path(__file__).resolve().parent.parent

CHILD = textwrap.dedent("""
    import sys, time
    import numpy as np
    from teleprev.messages import ImageSample, JointSample, Logged
    from teleprev.clock import SessionClock
    from teleprev.session.recorder import Recorder

    clock = SessionClock()
    rec = Recorder(sys.argv[1], {"session": {"task": "sigkill"}}).start()
    names = tuple(f"j{i}" for i in range(16))
    frame = np.random.default_rng(0).bytes(30_000)
    print("ready", flush=True)
    k, period, due = 0, 0.004, time.monotonic()
    while True:
        t = clock.now_ns()
        rec.log(Logged("/glove/g/hand", t, JointSample(t, names, np.full(16, float(k)))))
        if k % 8 == 0:
            rec.log(Logged("/camera/c/image", t, ImageSample(t, "c", frame)))
        k += 1
        due += period
        time.sleep(max(0.0, due - time.monotonic()))
""")


def test_sigkill_then_recover_keeps_everything_older_than_a_second(tmp_path):
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(2.5)
        kill_ns = time.time_ns()
        proc.send_signal(signal.SIGKILL)
        assert proc.wait(timeout=10) == -signal.SIGKILL
    finally:
        if proc.poll() is None:
            proc.kill()
    with pytest.raises(SessionError, match="teleprev recover"):
        SessionReader(path)
    result = recover(path)
    assert result.dst == tmp_path / "killed.recovered.mcap" and not result.complete
    assert path.stat().st_size == result.source_bytes  # the source is untouched
    with SessionReader(result.dst) as reader:
        assert reader.metadata["session"] == {"task": "sigkill"}
        glove = [(m.log_time_ns, m.payload.positions[0]) for m in reader.messages(["/glove/g/hand"])]
        assert reader.topics["/camera/c/image"].message_count == result.messages["/camera/c/image"] > 0
    # The child logged message k with value k in log-time order: no holes, and the last one kept was
    # logged less than a second before the kill, so every message logged before that is in the file.
    assert [v for _, v in glove] == list(range(len(glove)))
    assert len(glove) == result.messages["/glove/g/hand"] > 250
    assert kill_ns - glove[-1][0] < 1_000_000_000, f"lost {(kill_ns - glove[-1][0]) / 1e9:.3f} s"


def _raw_messages(path):
    """(topic, log_time, data) in file order, through the mcap library."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(c.topic, m.log_time, m.data) for _, c, m in make_reader(f).iter_messages(log_time_order=False)]


@pytest.fixture
def chunked(tmp_path):
    """A session of ~8 chunks (compressible values, so a chunk spans several zstd blocks)."""
    path = tmp_path / "full.mcap"
    names = tuple(f"joint_{i}" for i in range(24))
    with McapSessionWriter(path, {"session": {"task": "cut"}}) as w:
        for k in range(4000):
            w.write(Logged("/x" if k % 3 else "/y", 10_000 + k, JointSample(k, names, np.full(24, k % 7 / 8))))
            if k % 500 == 499:
                w.flush()
    return path


def test_cut_at_any_byte_recovers_a_prefix(chunked, tmp_path):
    full = _raw_messages(chunked)
    data = chunked.read_bytes()
    counts, salvaged = [], 0
    for i, cut in enumerate(np.linspace(0, len(data), 41).astype(int)):
        src = tmp_path / f"cut{i}.mcap"
        src.write_bytes(data[:cut])
        if cut < 8:
            with pytest.raises(SessionError, match="not an MCAP file"):
                recover(src)
            continue
        result = recover(src)
        got = _raw_messages(result.dst)
        assert got == full[: len(got)], f"cut at {cut}: not a prefix"
        assert result.total == len(got) and result.complete == (cut == len(data))
        counts.append(len(got))
        salvaged += result.salvaged
        if got:
            with SessionReader(result.dst) as reader:
                assert reader.metadata["session"] == {"task": "cut"}
    assert counts == sorted(counts) and counts[-1] == len(full)
    assert salvaged > 0  # some cuts fell inside a chunk and still gave up its first messages


def test_zero_filled_tail_and_damaged_chunk(chunked, tmp_path):
    data = bytearray(chunked.read_bytes())
    full = _raw_messages(chunked)
    with SessionReader(chunked) as reader:
        chunks = sorted(reader._chunks, key=lambda c: c.offset)
    second = chunks[1]

    zeros = tmp_path / "zeros.mcap"  # power loss: the file was extended but the blocks never written
    zeros.write_bytes(bytes(data[:second.offset]) + bytes(65536))
    result = recover(zeros)
    assert "opcode 0x00" in result.stop and result.valid_bytes == second.offset
    assert _raw_messages(result.dst) == full[:500]

    damaged = tmp_path / "damaged.mcap"
    data[second.offset + second.length - 100] ^= 0xFF
    damaged.write_bytes(bytes(data))
    result = recover(damaged)
    assert result.stop == "footer" and not result.complete
    (d,) = result.damaged  # only the damaged chunk is lost: the reading resynchronises after it
    assert d.start == second.offset and d.end >= second.offset + second.length
    assert (d.after_ns, d.before_ns) == (10_000 + 499, 10_000 + 1000)
    assert _raw_messages(result.dst) == full[:500] + full[1000:]


def _chunk_of(chunks, offset):
    return next((c for c in chunks if c.offset <= offset < c.offset + c.length), None)


def test_byte_flips_anywhere_lose_only_the_chunk_they_hit(chunked, tmp_path):
    """A flipped byte in a chunk's header, length, opcode or data costs that chunk's messages and nothing
    else; in the first chunk too (its channel records come back from the summary)."""
    data = chunked.read_bytes()
    full = _raw_messages(chunked)
    with SessionReader(chunked) as reader:
        chunks = sorted(reader._chunks, key=lambda c: c.offset)
    first_end = chunks[-1].offset + chunks[-1].length
    rng = np.random.default_rng(16)
    offsets = [chunks[0].offset, chunks[0].offset + 3, chunks[2].offset + 9 + 20, chunks[3].offset + 12]
    offsets += rng.integers(chunks[0].offset, first_end, 12).tolist()
    for i, at in enumerate(offsets):
        src = tmp_path / f"flip{i}.mcap"
        bad = bytearray(data)
        bad[at] ^= 1 << int(rng.integers(8))
        src.write_bytes(bytes(bad))
        result = recover(src)
        got = {(t, lt) for t, lt, _ in _raw_messages(result.dst)}
        hit = _chunk_of(chunks, at)
        lost = {(t, lt) for t, lt, _ in full} - got
        if hit is None:  # between chunks (a message index): nothing is lost
            assert not lost, at
            continue
        assert all(hit.start_ns <= lt <= hit.end_ns for _, lt in lost), f"flip at {at} lost more than its chunk"
        for d in result.damaged:
            assert d.after_ns is None or d.after_ns < hit.start_ns
            assert d.before_ns is None or d.before_ns > hit.end_ns


def test_damage_and_a_cut_tail_together(chunked, tmp_path):
    data = bytearray(chunked.read_bytes())
    full = _raw_messages(chunked)
    with SessionReader(chunked) as reader:
        chunks = sorted(reader._chunks, key=lambda c: c.offset)
    data[chunks[1].offset + 40] ^= 0x10
    cut = chunks[5].offset + chunks[5].length // 2
    src = tmp_path / "both.mcap"
    src.write_bytes(bytes(data[:cut]))
    result = recover(src)
    assert len(result.damaged) == 1 and "cut off by the end of the file" in result.stop
    got = _raw_messages(result.dst)
    assert got[:500] == full[:500] and got[500:2000] == full[1000:2500]  # chunks 2-4 all there
    assert got[2000:] == full[2500:2500 + len(got) - 2000]  # and what of chunk 5 decompresses


def test_recover_refuses_bad_paths(chunked, tmp_path):
    with pytest.raises(SessionError, match="no such session file"):
        recover(tmp_path / "missing.mcap")
    text = tmp_path / "notes.mcap"
    text.write_text("hello, not a recording\n")
    with pytest.raises(SessionError, match="not an MCAP file") as exc:
        recover(text)
    assert str(text) in str(exc.value)
    with pytest.raises(SessionError, match="must not replace its source"):
        recover(chunked, chunked)
    first = recover(chunked)
    assert first.complete and first.stop == "footer"
    with pytest.raises(SessionError, match="already exists"):
        recover(chunked)
    assert os.path.exists(first.dst)
