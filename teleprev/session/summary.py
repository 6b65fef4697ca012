"""The facts `teleprev info` prints about a session: streams, rates, gaps, drops, device events, episodes.

Rates and gaps come from the message indexes (log times only, nothing decompressed), drops from the
recorder's metadata record (absent in a file rewritten by `teleprev recover`: the recorder never closed).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev.errors import SessionError
from teleprev.messages import Event
from teleprev.session.reader import Episode, SessionReader
from teleprev.session.recorder import RECORDER_RECORD
from teleprev.topics import COMMAND_ARM, COMMAND_HAND, COMMAND_TICK, DEVICE_EVENT, MODE

GAP_FACTOR = 3.0  # a gap is an interval longer than this many median periods
PREVIEW_ONLY = ("the robot was never engaged: the whole session ran in PREVIEW, so no command was sent or recorded "
                "and there are no actions to export (record with --engage-after SECONDS, or press space to execute)")


def device_lost(counts: dict[str, int]) -> int:
    """All a device lost before its samples were recorded, from its counts in the "devices" record: what it
    knew it lost before reading it, what the session loop had no room for, what its runner could not hand on."""
    return counts.get("lost_input", 0) + counts.get("loop_dropped", 0) + counts.get("sink_errors", 0)


def is_preview_only(session_topics) -> bool:
    """Whether a recorded session holds no command at all (the robot was never engaged); a bimanual session's
    commands are on its sides' topics (/command/left/arm, ...)."""
    return not any(t in (COMMAND_ARM, COMMAND_HAND) or (t.startswith("/command/") and t.endswith(("/arm", "/hand")))
                   for t in session_topics)


@dataclass
class StreamSummary:
    topic: str
    schema: str
    count: int
    rate_hz: float | None  # (count - 1) / (last - first); None with fewer than two messages
    first_ns: int | None
    last_ns: int | None
    max_gap_s: float | None  # largest interval between consecutive messages
    gaps: int  # intervals longer than GAP_FACTOR x the median interval
    backwards: int  # log times that went back from the previous message (0 for a monotonic stream)
    received: int | None = None  # from the recorder's counters, when the file has them
    dropped: int | None = None
    errors: int | None = None


@dataclass
class DeviceEventInfo:
    log_time_ns: int
    device: str
    event: str
    message: str


@dataclass
class SenderSummary:
    """The paced command sender's timing in a session: from its ticks (/command/tick)."""

    ticks: int
    rate_hz: float | None
    realtime: bool | None  # it ran with real-time priority (None: not recorded)
    late_ms_p50: float
    late_ms_p99: float
    late_ms_max: float
    gap_ms_max: float  # the longest interval between two commands of one engaged run (stamps)

    @classmethod
    def from_ticks(cls, stamps: list[int], late_ms: list[float], active: list[bool], engages_ns: list[int],
                   meta: dict[str, str]) -> SenderSummary:
        late = np.asarray(late_ms, dtype=float)
        gap = 0.0
        if len(stamps) > 1:
            t = np.asarray(stamps, dtype=np.int64)
            starts = np.searchsorted(t, np.asarray(engages_ns, dtype=np.int64), side="left")
            same_run = np.asarray(active[:-1], dtype=bool)  # a tick after an inactive one starts a new run
            starts = starts[(starts > 0) & (starts < len(t))]
            same_run[starts - 1] = False  # so does the first after an engage
            d = np.diff(t)[same_run]
            gap = float(d.max()) / 1e6 if len(d) else 0.0
        realtime = meta.get("realtime")
        rate = meta.get("rate_hz")
        return cls(len(stamps), float(rate) if rate else None, None if realtime is None else realtime == "true",
                   float(np.percentile(late, 50)) if len(late) else 0.0,
                   float(np.percentile(late, 99)) if len(late) else 0.0, float(late.max()) if len(late) else 0.0, gap)

    @classmethod
    def from_session(cls, reader: SessionReader, tick_topic: str = COMMAND_TICK,
                     meta: dict[str, str] | None = None) -> SenderSummary:
        """From a session's ticks on `tick_topic` (a bimanual session's sides: /command/<side>/tick) and its
        engages; `meta`: the file's "sender" record."""
        stamps, late, active, engages = [], [], [], []
        for msg in reader.messages([tick_topic, MODE]):
            ev = msg.payload
            if not isinstance(ev, Event):
                continue
            if msg.topic == MODE:
                if ev.data.get("mode") == "execute":
                    engages.append(msg.log_time_ns)
                continue
            stamps.append(ev.stamp_ns)
            late.append(float(ev.data.get("late_ms", 0.0)))
            active.append(bool(ev.data.get("active", True)))
        return cls.from_ticks(stamps, late, active, engages, meta or {})


@dataclass
class SessionSummary:
    path: Path
    file_bytes: int
    start_ns: int | None
    end_ns: int | None
    message_count: int
    streams: list[StreamSummary]
    episodes: list[Episode]
    device_events: list[DeviceEventInfo]
    metadata: dict[str, dict[str, str]]
    has_recorder_counters: bool
    recovered: bool  # rewritten by `teleprev recover`
    dropped: int | None = None
    recorder_errors: list[str] = field(default_factory=list)
    # Per device (the "devices" metadata record a live session writes when it closes): samples received,
    # the device's lost_/skipped counters, lost_input (their total), loop_dropped, sink_errors, failures.
    device_counts: dict[str, dict[str, int]] = field(default_factory=dict)
    sender: SenderSummary | None = None  # the paced command sender's timing (None: no /command/tick)

    @property
    def duration_s(self) -> float:
        return 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9

    @property
    def preview_only(self) -> bool:
        return is_preview_only({st.topic for st in self.streams if st.count})

    @property
    def device_failures(self) -> dict[str, int]:
        """Failures (connect or read raised: "error" events) per device; skipped input is not one
        (older sessions reported it as an "error" whose message starts with "skipped")."""
        out: dict[str, int] = {}
        for e in self.device_events:
            if e.event == "error" and not e.message.startswith("skipped "):
                out[e.device] = out.get(e.device, 0) + 1
        return out

    def to_json(self) -> dict:
        from dataclasses import asdict

        out = asdict(self)
        out["path"] = str(self.path)
        out["duration_s"] = self.duration_s
        out["device_failures"] = self.device_failures
        out["preview_only"] = self.preview_only
        return out


def interval_stats(times: np.ndarray) -> tuple[float | None, int, int]:
    """(largest interval in s, intervals > GAP_FACTOR x median, backward steps) of log times in file order."""
    if len(times) < 2:
        return None, 0, 0
    d = np.diff(times)
    backwards = int((d < 0).sum())
    ordered = np.diff(np.sort(times))
    median = float(np.median(ordered))
    gaps = int((ordered > GAP_FACTOR * median).sum()) if median > 0 else 0
    return float(ordered.max()) / 1e9, gaps, backwards


def summarize(path: str | os.PathLike) -> SessionSummary:
    """The session's facts; every chunk is read and CRC-checked first, and a damaged one is an error
    naming its time range (`teleprev recover` keeps the rest)."""
    with SessionReader(path) as reader:
        damaged = reader.damaged_chunks()
        if damaged:
            where = "; ".join(f"{reader.describe_chunk(c)} ({why})" for c, why in damaged[:3])
            more = f" and {len(damaged) - 3} more" if len(damaged) > 3 else ""
            raise SessionError(f"{len(damaged)} damaged chunk{'s' if len(damaged) > 1 else ''}: {where}{more}; "
                               f"`teleprev recover {reader.path}` keeps everything else", str(reader.path))
        if reader.data_section_intact() is False:
            raise SessionError("bytes were changed outside the chunks (a message index or metadata record): the data "
                               f"section's CRC does not match; `teleprev recover {reader.path}` rebuilds the file",
                               str(reader.path))
        meta = reader.metadata
        counters = meta.get(RECORDER_RECORD, {})
        streams = []
        for topic, info in reader.topics.items():
            times = reader.log_times(topic)
            max_gap, gaps, backwards = interval_stats(times)
            rate = None
            if info.message_count >= 2 and info.last_ns > info.first_ns:
                rate = (info.message_count - 1) / ((info.last_ns - info.first_ns) / 1e9)
            s = StreamSummary(topic, info.schema, info.message_count, rate, info.first_ns, info.last_ns, max_gap,
                              gaps, backwards)
            if topic in counters:
                c = _counters(counters[topic], reader.path, topic)
                s.received, s.dropped, s.errors = c.get("received"), c.get("dropped"), c.get("errors")
            streams.append(s)
        # Topics the recorder saw but never wrote (everything dropped or rejected) still show up.
        for key, value in counters.items():
            if key.startswith("/") and key not in reader.topics:
                c = _counters(value, reader.path, key)
                streams.append(StreamSummary(key, "", 0, None, None, None, None, 0, 0, c.get("received"),
                                             c.get("dropped"), c.get("errors")))
        device_events = []
        if DEVICE_EVENT in reader.topics:
            for msg in reader.messages([DEVICE_EVENT]):
                ev = msg.payload
                if isinstance(ev, Event):
                    d = ev.data
                    device_events.append(DeviceEventInfo(msg.log_time_ns, str(d.get("device", "")),
                                                         str(d.get("event", "")), str(d.get("message", ""))))
        sender = None
        if COMMAND_TICK in reader.topics:
            sender = SenderSummary.from_session(reader, COMMAND_TICK, meta.get("sender", {}))
        has_counters = bool(counters)
        return SessionSummary(
            reader.path, reader.file_bytes, reader.start_ns, reader.end_ns,
            sum(s.count for s in streams), streams, reader.episodes(), device_events, meta, has_counters,
            "recover" in meta,
            sum(s.dropped or 0 for s in streams) if has_counters else None,
            [f"{k[6:]}: {v}" for k, v in counters.items() if k.startswith("error ")],
            {name: _counters(value, reader.path, f"device {name}") for name, value in meta.get("devices", {}).items()},
            sender,
        )


def _counters(value: str, path: Path, topic: str) -> dict[str, int]:
    try:
        c = json.loads(value)
        if not isinstance(c, dict):
            raise ValueError("not an object")
        return {k: int(v) for k, v in c.items()}
    except (ValueError, TypeError) as exc:
        raise SessionError(f"recorder counters for {topic} are malformed ({exc}): {value!r}", str(path)) from None
