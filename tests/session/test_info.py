"""`teleprev info`: streams, rates, gaps, drops, device events, episodes and duration of a recorded file;
and clear errors for files that are not sessions."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from teleprev import topics as T
from teleprev.cli.app import app
from teleprev.errors import SessionError
from teleprev.messages import Event, JointSample, Logged
from teleprev.session.reader import Episode, SessionReader
from teleprev.session.recorder import Recorder
from teleprev.session.summary import summarize
from tests.helpers.cli import teleprev

T0 = 1_750_000_000_000_000_000
MS = 1_000_000
GLOVE, ARM, HAND = "/glove/right/hand", "/arm/xarm/state", "/hand/leap/state"


def _episode(t, **data):
    return Logged(T.EPISODE, t, Event(t, "teleprev.EpisodeEvent", data))


def _device(t, **data):
    return Logged(T.DEVICE_EVENT, t, Event(t, "teleprev.DeviceEvent", data))


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A 10 s session through the Recorder: glove at 100 Hz with one 500 ms hole, arm at 50 Hz whose
    last 5 messages are dropped (queue full), a hand stream with one log time out of order, device
    gap / recovered events around the hole, and three episodes (finished, discarded, never stopped)."""
    msgs = []
    for k in range(1000):
        t = T0 + k * 10 * MS
        if not 400 <= k < 450:
            msgs.append(Logged(GLOVE, t, JointSample(t, ("a", "b"), np.array([k, 0.5]))))
    for k in range(200):
        t = T0 + k * 20 * MS
        msgs.append(Logged(HAND, t + (30 * MS if k == 100 else 0), JointSample(t, ("0",), np.array([0.1]))))
    msgs += [
        _device(T0 + 4_030 * MS, device="right", event="gap", message="no data for 30 ms", since_ns=T0 + 3_990 * MS),
        _device(T0 + 4_500 * MS, device="right", event="recovered"),
        _episode(T0 + 1_000 * MS, event="start", episode=0, task="pour water"),
        _episode(T0 + 3_000 * MS, event="stop", episode=0),
        _episode(T0 + 3_100 * MS, event="outcome", episode=0, outcome="success"),
        _episode(T0 + 5_000 * MS, event="start", episode=1, task="pour water"),
        _episode(T0 + 6_500 * MS, event="discard", episode=1),
        _episode(T0 + 8_000 * MS, event="start", episode=2, task="stack"),
    ]
    msgs.sort(key=lambda m: m.payload.stamp_ns)  # logged in acquisition order: one hand log time steps back
    arm = [Logged(ARM, T0 + k * 20 * MS, JointSample(T0 + k * 20 * MS, ("j1",), np.array([0.0]))) for k in range(500)]
    path = tmp_path_factory.mktemp("info") / "session.mcap"
    # Not started, so nothing drains the queue: it holds everything but the last 5 arm messages.
    rec = Recorder(path, {"session": {"operator": "ann", "task": "pour water"}}, queue_size=len(msgs) + 495)
    for m in msgs + arm:
        rec.log(m)
    rec.close()
    return path


def test_summary_facts(recorded):
    s = summarize(recorded)
    by = {st.topic: st for st in s.streams}
    assert set(by) == {GLOVE, ARM, HAND, T.EPISODE, T.DEVICE_EVENT}
    glove = by[GLOVE]
    assert glove.count == 950 and glove.dropped == 0 and glove.received == 950
    assert glove.rate_hz == pytest.approx(949 / 9.99)
    assert glove.max_gap_s == pytest.approx(0.51) and glove.gaps == 1 and glove.backwards == 0
    arm = by[ARM]
    assert (arm.count, arm.received, arm.dropped) == (495, 500, 5)
    assert arm.rate_hz == pytest.approx(50.0) and arm.gaps == 0
    assert by[HAND].backwards == 1 and by[HAND].count == 200
    assert s.dropped == 5 and s.has_recorder_counters and not s.recovered
    assert s.duration_s == pytest.approx(9.99)
    assert s.start_ns == T0 and s.file_bytes == recorded.stat().st_size
    assert [(d.device, d.event) for d in s.device_events] == [("right", "gap"), ("right", "recovered")]
    assert s.episodes == [
        Episode(0, "pour water", T0 + 1_000 * MS, T0 + 3_000 * MS, False, "success", marked="success"),
        Episode(1, "pour water", T0 + 5_000 * MS, T0 + 6_500 * MS, True, None),
        Episode(2, "stack", T0 + 8_000 * MS, None, False, None),
    ]
    with SessionReader(recorded) as reader:
        times = [m.log_time_ns for m in reader.messages()]
    assert times == sorted(times) and len(times) == s.message_count


def test_info_command_prints_the_tables(recorded):
    result = CliRunner().invoke(app, ["info", str(recorded)])
    assert result.exit_code == 0, result.output
    out = result.output
    for text in (GLOVE, ARM, "950", "495", "pour water", "stack", "not stopped", "success", "operator", "ann",
                 "gap", "recovered", "9.990 s"):
        assert text in out, text
    glove_row = next(line for line in out.splitlines() if GLOVE in line)
    assert glove_row.split()[1:7] == ["JointStates", "950", "94.99", "510.0", "1", "0"]
    arm_row = next(line for line in out.splitlines() if ARM in line)
    assert arm_row.split()[2:4] == ["495", "50.00"] and arm_row.split()[6] == "5"

    as_json = json.loads(CliRunner().invoke(app, ["info", str(recorded), "--json"]).output)
    assert as_json["dropped"] == 5 and as_json["duration_s"] == pytest.approx(9.99)
    assert {s["topic"]: s["count"] for s in as_json["streams"]}[GLOVE] == 950


def test_recover_command_and_info_on_the_result(recorded, tmp_path):
    cut = tmp_path / "cut.mcap"
    data = recorded.read_bytes()
    cut.write_bytes(data[: len(data) * 2 // 3])
    result = CliRunner().invoke(app, ["recover", str(cut), "--out", str(tmp_path / "saved.mcap")])
    assert result.exit_code == 0, result.output
    assert "saved" in result.output and GLOVE in result.output and "bytes make sense" in result.output
    info = CliRunner().invoke(app, ["info", str(tmp_path / "saved.mcap")])
    assert info.exit_code == 0 and "rewritten by `teleprev recover`" in info.output


@pytest.mark.parametrize("content, message", [
    (None, "no such session file"),
    (b"", "empty file"),
    (b"timestamp,value\n1,2\n", "not an MCAP file"),
    (b"\x89MCAP0\r\n" + bytes(200), "cut short or damaged"),
])
def test_bad_files_name_the_file(tmp_path, content, message):
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(SessionError, match=message) as exc:
        SessionReader(path)
    assert exc.value.where == str(path)


def test_truncated_file_points_at_recover(recorded, tmp_path):
    cut = tmp_path / "half.mcap"
    cut.write_bytes(recorded.read_bytes()[:5000])
    with pytest.raises(SessionError) as exc:
        summarize(cut)
    assert f"teleprev recover {cut}" in str(exc.value) and str(cut) in str(exc.value)
    # Through the real entry point: one line on stderr, exit status 2, no traceback.
    proc = teleprev("info", cut)
    assert proc.returncode == 2 and "teleprev recover" in proc.stderr and "Traceback" not in proc.stderr


def test_info_reports_the_command_senders_timing(tmp_path):
    """Format 4: the sender's ticks give its lateness and the longest gap between commands of one engaged
    run (a pause while in preview, between two engages, is none)."""
    tick = lambda t, late, active=True: Logged(T.COMMAND_TICK, t, Event(t, "teleprev.CommandTick", {  # noqa: E731
        "seq": 1, "late_ms": late, "flags": [], "active": active}))
    mode = lambda t, m: Logged(T.MODE, t, Event(t, "teleprev.ModeSwitch", {"mode": m}))  # noqa: E731
    period = 8_333_333
    msgs = [mode(T0, "execute")] + [tick(T0 + k * period, 0.05 + 0.01 * (k % 7)) for k in range(1, 200)]
    msgs.append(tick(T0 + 200 * period + 30 * MS, 30.0))  # one tick 30 ms late: a 38 ms gap
    msgs += [tick(T0 + (201 + k) * period + 30 * MS, 0.05, active=k < 49) for k in range(50)]  # braked, stopped
    msgs += [mode(T0 + 4_000 * MS, "execute")] + [tick(T0 + 4_000 * MS + k * period, 0.05) for k in range(1, 50)]
    path = tmp_path / "s.mcap"
    rec = Recorder(path, {"sender": {"rate_hz": "120", "realtime": "true"}})
    rec.start()
    for m in sorted(msgs, key=lambda m: m.log_time_ns):
        rec.log(m)
    rec.close()
    s = summarize(path).sender
    assert s.ticks == 299 and s.rate_hz == 120.0 and s.realtime is True
    assert s.late_ms_max == 30.0 and s.late_ms_p50 == pytest.approx(0.05, abs=0.02)
    assert s.gap_ms_max == pytest.approx(period / 1e6 + 30.0, abs=1e-6)
    out = " ".join(CliRunner().invoke(app, ["info", str(path)]).output.split())
    assert "command sender 120 Hz, real-time priority: 299 ticks" in out and "38.3 ms" in out
