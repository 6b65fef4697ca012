"""The Recorder: bounded queue, drops counted (never blocking), one writer thread, counters kept in the file."""

from __future__ import annotations

import json
import threading
import time

import numpy as np
import pytest

from teleprev.errors import SessionError
from teleprev.messages import Event, JointSample, Logged
from teleprev.session.reader import SessionReader
from teleprev.session.recorder import RECORDER_RECORD, Recorder
from tests.helpers.wait import wait_until

NAMES = ("a", "b")


def joint(topic: str, t: int, value: float = 0.0) -> Logged:
    return Logged(topic, t, JointSample(t, NAMES, np.array([value, -value])))


def test_counts_and_file_agree(tmp_path):
    path = tmp_path / "r.mcap"
    with Recorder(path, {"session": {"operator": "ann"}}) as rec:
        for k in range(500):
            assert rec.log(joint("/glove/g/hand", 1000 + k, k))
            if k % 5 == 0:
                assert rec.log(joint("/arm/a/state", 1000 + k, -k))
    summary = rec.close()
    assert summary.streams["/glove/g/hand"].written == 500 and summary.streams["/arm/a/state"].written == 100
    assert summary.dropped == 0 and summary.written == 600 and summary.file_bytes == path.stat().st_size
    assert summary.streams["/glove/g/hand"].bytes > 500 * 30
    with SessionReader(path) as reader:
        assert {t: i.message_count for t, i in reader.topics.items()} == {"/glove/g/hand": 500, "/arm/a/state": 100}
        values = [m.payload.positions[0] for m in reader.messages(["/glove/g/hand"])]
        counters = json.loads(reader.metadata[RECORDER_RECORD]["/glove/g/hand"])
        assert reader.metadata["session"] == {"operator": "ann"}
    assert values == list(range(500))
    assert counters == {"received": 500, "written": 500, "dropped": 0, "errors": 0,
                        "bytes": summary.streams["/glove/g/hand"].bytes, "shed": 0}


def test_full_queue_drops_and_counts_without_blocking(tmp_path):
    """Before start() nothing drains the queue: with room for 3, the 4th message on is dropped at once."""
    path = tmp_path / "d.mcap"
    rec = Recorder(path, {}, queue_size=3)
    t = time.perf_counter()
    accepted = [rec.log(joint("/x", k)) for k in range(10)] + [rec.log(joint("/y", 99))]
    assert time.perf_counter() - t < 0.5
    assert accepted == [True] * 3 + [False] * 8
    stats = rec.stats()
    assert (stats["/x"].received, stats["/x"].dropped, stats["/y"].dropped) == (10, 7, 1)
    summary = rec.close()
    assert summary.streams["/x"].written == 3 and summary.dropped == 8
    assert not rec.log(joint("/x", 100))  # closed: refused
    with SessionReader(path) as reader:
        assert [m.log_time_ns for m in reader.messages()] == [0, 1, 2]
        assert "/y" not in reader.topics
        assert json.loads(reader.metadata[RECORDER_RECORD]["/y"])["dropped"] == 1


def test_many_producer_threads(tmp_path):
    """received == written + dropped per topic, and every producer's accepted messages are in the file
    in the order it logged them."""
    path = tmp_path / "m.mcap"
    rec = Recorder(path, {}, queue_size=64).start()
    accepted: dict[str, list[int]] = {}

    def produce(i: int) -> None:
        topic = f"/dev/p{i}/state"
        accepted[topic] = [k for k in range(3000) if rec.log(joint(topic, k, k))]

    threads = [threading.Thread(target=produce, args=(i,)) for i in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    summary = rec.close()
    assert summary.dropped > 0 and summary.max_queue_depth <= 64  # producers outran the writer
    with SessionReader(path) as reader:
        for topic, ks in accepted.items():
            st = summary.streams[topic]
            assert st.received == 3000 and st.written == len(ks) and st.written + st.dropped == 3000
            # a producer whose every message met a full queue has no channel in the file at all
            in_file = [m.payload.positions[0] for m in reader.messages([topic])] if topic in reader.topics else []
            assert in_file == ks


def test_bad_messages_are_counted_not_fatal(tmp_path):
    path = tmp_path / "e.mcap"
    with Recorder(path, {}) as rec:
        rec.log(joint("/x", 1))
        rec.log(Logged("/x", 2, JointSample(2, ("only",), np.array([1.0, 2.0]))))  # names and values disagree
        rec.log(Logged("/ev", 3, Event(3, "teleprev.Unknown", {})))
        rec.log(joint("/x", 4))
    summary = rec.close()
    assert summary.streams["/x"].written == 2 and summary.streams["/x"].errors == 1
    assert summary.streams["/ev"].errors == 1
    assert any("positions has 2 values" in e for e in summary.errors)
    with SessionReader(path) as reader:
        assert [m.log_time_ns for m in reader.messages()] == [1, 4]
        assert "unknown event schema" in reader.metadata[RECORDER_RECORD]["error /ev"]


def test_flushes_while_recording(tmp_path):
    """With flush_interval_s=0.1, a copy of the file taken mid-session recovers what was logged
    more than the interval before."""
    from teleprev.session.recover import recover

    path = tmp_path / "f.mcap"
    rec = Recorder(path, {}, flush_interval_s=0.1).start()
    for k in range(50):
        rec.log(joint("/x", k, k))
    wait_until(lambda: rec.stats()["/x"].written == 50, what="50 messages written")
    time.sleep(0.3)  # what is under test: three flush intervals later, they are in the file
    snapshot = tmp_path / "snap.mcap"
    snapshot.write_bytes(path.read_bytes())
    rec.log(joint("/x", 50, 50))
    rec.close()
    assert recover(snapshot).messages == {"/x": 50}


def test_a_kill_at_any_moment_loses_at_most_a_quarter_second_of_what_was_written(tmp_path):
    """What a SIGKILL leaves is what was flushed: the file up to its last whole chunk. Watched every 5 ms over a
    second, the newest message the file keeps is never more than 0.35 s behind the clock (the default flush
    interval and the writer's wake-up). bench/faults.py lost 1.043 s to a SIGKILL at load 24 with the 0.5 s
    interval: half a second of interval on top of the writer's lag is most of the second an operator may lose."""
    from tests.helpers.faults import chunk_spans

    path = tmp_path / "k.mcap"
    rec = Recorder(path, {}).start()
    seen: list[tuple[int, int]] = []  # (clock, the file's size then)
    end = time.monotonic() + 1.5
    while time.monotonic() < end:
        now = time.time_ns()
        rec.log(joint("/x", now))
        seen.append((now, path.stat().st_size))
        time.sleep(0.005)
    rec.close()
    chunks = chunk_spans(path)
    lost = []
    for now, size in seen[len(seen) // 2:]:  # from 0.75 s: a kill before the first flush keeps nothing
        kept = [c[3] for c in chunks if c[0] + c[1] <= size]
        lost.append((now - max(kept)) / 1e9 if kept else float("inf"))
    assert max(lost) < 0.35, max(lost)


def test_writer_cpu_and_arguments(tmp_path):
    rec = Recorder(tmp_path / "c.mcap", {}).start()
    for k in range(200):
        rec.log(joint("/x", k))
    summary = rec.close()
    assert 0 < summary.writer_cpu_s < summary.wall_s + 1
    with pytest.raises(ValueError, match="flush_interval_s"):
        Recorder(tmp_path / "z.mcap", {}, flush_interval_s=2.0)
    with pytest.raises(SessionError, match="does not overwrite"):
        Recorder(tmp_path / "c.mcap", {})


def test_io_failure_stops_cleanly_and_keeps_what_was_flushed(tmp_path):
    """The file descriptor stops accepting writes under the writer (as on a dead disk): log() starts refusing,
    close() raises a SessionError pointing at recover, and recover gets back what was flushed."""
    import os

    from teleprev.session.recover import recover

    path = tmp_path / "io.mcap"
    rec = Recorder(path, {}, flush_interval_s=0.05).start()
    for k in range(20):
        rec.log(joint("/x", k, k))
    wait_until(lambda: rec.stats()["/x"].written == 20, what="20 messages written")
    time.sleep(0.2)  # at least one flush after the last write
    read_only = os.open(os.devnull, os.O_RDONLY)
    os.dup2(read_only, rec._writer._file.fileno())  # the writer's descriptor now refuses writes
    os.close(read_only)

    def failed():
        rec.log(joint("/x", 100, 100))
        return rec.failure

    assert isinstance(wait_until(failed, 5, what="the writer's failure"), OSError)
    assert not rec.log(joint("/x", 101, 101))
    with pytest.raises(SessionError, match="teleprev recover"):
        rec.close()
    assert recover(path).messages == {"/x": 20}


def test_close_checks_extra_metadata_first(tmp_path):
    rec = Recorder(tmp_path / "x.mcap", {}).start()
    rec.log(joint("/x", 1))
    with pytest.raises(ValueError, match="key 'ok' -> True"):
        rec.close({"outcome": {"ok": True}})
    assert rec.log(joint("/x", 2))  # still recording
    rec.close({"outcome": {"ok": "yes"}})
    with SessionReader(tmp_path / "x.mcap") as reader:
        assert reader.metadata["outcome"] == {"ok": "yes"} and reader.topics["/x"].message_count == 2
