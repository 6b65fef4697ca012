"""Episodes of a foreign file, as the import recipe's [import] table says: the whole file, the spans
between "start" and "stop" messages on an events topic, or the runs of a stream between silences longer
than gap_s. Times are the streams' stamps (the same clock the frames are planned on)."""

from __future__ import annotations

import numpy as np

from teleprev.errors import SessionError
from teleprev.export.foreign.config import ImportSection
from teleprev.messages import Event
from teleprev.session.reader import Episode

START_WORDS = ("start", "begin")
STOP_WORDS = ("stop", "end", "done")
_NS = 1_000_000_000


def cut_episodes(reader, section: ImportSection, joint_topics: list[str]) -> list[Episode]:
    """`reader` has SessionReader's surface; `joint_topics` are the recipe's joint streams (the default
    gap_topic is the first)."""
    task = section.task
    if section.episodes == "file":
        if reader.start_ns is None:
            return []
        # stamps come before log times: the episode starts at the earliest stamp logged in the first second
        first = [m.payload.stamp_ns for m in reader.messages(None, reader.start_ns, reader.start_ns + _NS)]
        start = min([int(reader.start_ns)] + [int(s) for s in first if s > 0])
        return [Episode(0, task, start, int(reader.end_ns) + 1, False, None)]
    if section.episodes == "gaps":
        topic = section.gap_topic or (joint_topics[0] if joint_topics else "")
        if topic not in reader.topics:
            raise SessionError(f'[import] gap_topic {topic or "(none)"!r} is not in this file '
                               f"(topics: {', '.join(sorted(reader.topics))})", str(reader.path))
        stamps = np.array(sorted(m.payload.stamp_ns for m in reader.messages([topic])), dtype=np.int64)
        if not len(stamps):
            return []
        cuts = np.flatnonzero(np.diff(stamps) > int(section.gap_s * 1e9)) + 1
        starts, stops = np.r_[0, cuts], np.r_[cuts, len(stamps)]
        return [Episode(i, task, int(stamps[a]), int(stamps[b - 1]) + 1, False, None)
                for i, (a, b) in enumerate(zip(starts.tolist(), stops.tolist()))]
    return _from_events(reader, section, task)


def _from_events(reader, section: ImportSection, task: str) -> list[Episode]:
    topic = section.events_topic
    if topic not in reader.topics:
        raise SessionError(f"[import] events_topic {topic!r} is not in this file "
                           f"(topics: {', '.join(sorted(reader.topics))})", str(reader.path))
    out: list[Episode] = []
    open_at: int | None = None
    for msg in reader.messages([topic]):
        word = _word(msg.payload)
        if word is None:
            raise SessionError(f"{topic} at log time {msg.log_time_ns}: expected a text or JSON event, got "
                               f"{type(msg.payload).__name__}", str(reader.path))
        t = msg.payload.stamp_ns or msg.log_time_ns
        if word.startswith(START_WORDS):
            if open_at is not None:  # a start while one runs: the running one ends here
                out.append(Episode(len(out), task, open_at, t, False, None))
            open_at = t
        elif word.startswith(STOP_WORDS) and open_at is not None:
            out.append(Episode(len(out), task, open_at, t, False, None))
            open_at = None
    if open_at is not None:
        out.append(Episode(len(out), task, open_at, None, False, None))
    return out


def _word(payload) -> str | None:
    """The lower-cased text of an event message: std_msgs/String's data, or a JSON object's "event"
    (teleprev's own episode events), "data" or "text" field."""
    if not isinstance(payload, Event):
        return None
    for key in ("event", "data", "text"):
        value = payload.data.get(key)
        if isinstance(value, str):
            return value.strip().lower()
    return ""
