"""The session recorder: any number of producer threads, one bounded queue, one writer thread.

`log()` never blocks and never raises for a full queue: the message is dropped and counted, so a slow
disk cannot stall a device or the pipeline. Encoding, compression and file I/O all happen on the writer
thread, which ends a chunk and flushes it to the OS every `flush_interval_s`, so a crash or a kill loses
at most that much, plus what is still queued. At close, a "recorder" metadata record keeps every stream's
counters in the file.

What is queued is bounded in time, not only in count: a full disk loses what was not flushed, so a writer
that falls behind (a busy machine) would stretch the loss past a second. Recording what is already in
memory comes first: the writer thread runs at a raised priority (teleprev/thread_priority.py's WRITER_NICE),
and while the oldest queued
message is older than `lag_budget_s`, new work is shed, the least valuable first: camera frames, then
(past twice the budget) every stream but the commands and the events. Shed messages are counted per
stream (`shed`, also in `dropped`), and `on_behind(behind, lag_s, shed)` tells the session when the writer
falls behind and when it has caught up, on the writer thread.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from teleprev.errors import SessionError, describe_os_error
from teleprev.messages import DepthSample, Event, ImageSample, Logged
from teleprev.session.writer import DEFAULT_CHUNK_SIZE, McapSessionWriter, check_metadata
from teleprev.thread_priority import WRITER_NICE, raise_this_thread

RECORDER_RECORD = "recorder"  # metadata record with the counters, written at close
DEFAULT_QUEUE_SIZE = 4096
POLL_S = 0.02  # how often the idle writer looks at the queue
# A kill loses what was not flushed: up to this, plus the writer's lag. At 0.5 s, a SIGKILL lost 1.043 s at
# load 24 on 2 cores (bench/faults.py); the cost is a chunk record per interval (a 6 s session: 24, not 12).
FLUSH_INTERVAL_S = 0.25
YIELD_EVERY = 16  # messages the writer encodes before letting producers have the GIL
# The oldest queued message older than this: new camera frames are shed (past twice this: all but commands, events).
LAG_BUDGET_S = 0.3
COMMAND_PREFIX = "/command/"


@dataclass(slots=True)
class StreamStats:
    """Per topic: messages handed to log(), written to the file, dropped (the queue was full, or shed),
    shed because the writer was behind, rejected because they could not be encoded (errors), and encoded
    bytes written."""

    received: int = 0
    written: int = 0
    dropped: int = 0
    bytes: int = 0
    errors: int = 0
    shed: int = 0

    def as_json(self) -> str:
        return json.dumps({"received": self.received, "written": self.written, "dropped": self.dropped,
                           "errors": self.errors, "bytes": self.bytes, "shed": self.shed})


@dataclass
class RecordingSummary:
    path: Path
    streams: dict[str, StreamStats]
    wall_s: float  # start() to close()
    writer_cpu_s: float  # CPU time of the writer thread (encoding, compression, I/O)
    max_queue_depth: int
    file_bytes: int
    errors: list[str] = field(default_factory=list)  # first rejection message per topic
    max_lag_s: float = 0.0  # the oldest queued message's age, at its largest

    @property
    def shed(self) -> int:
        return sum(s.shed for s in self.streams.values())

    @property
    def written(self) -> int:
        return sum(s.written for s in self.streams.values())

    @property
    def dropped(self) -> int:
        return sum(s.dropped for s in self.streams.values())


_STOP = object()


class Recorder:
    def __init__(
        self,
        path: str | os.PathLike,
        metadata: dict[str, dict[str, str]] | None = None,
        *,
        queue_size: int = DEFAULT_QUEUE_SIZE,
        flush_interval_s: float = FLUSH_INTERVAL_S,
        chunk_size: int = DEFAULT_CHUNK_SIZE,
        fsync: bool = True,
        on_failure: Callable[[BaseException], None] | None = None,
        attachments: dict[str, tuple[str, bytes]] | None = None,
        lag_budget_s: float | None = None,
        on_behind: Callable[[bool, float, dict[str, int]], None] | None = None,
    ):
        """`on_failure(exc)` is called once, on the writer thread, the moment a write or flush fails (a full
        disk, a dead drive): at most one flush interval after the data it could not write was logged.
        `lag_budget_s`: shed new work past this lag (None: never; a live session's is LAG_BUDGET_S, a replay
        written faster than real time sheds nothing).
        `on_behind(behind, lag_s, shed)`: the writer fell behind by more than `lag_budget_s` (True), or caught
        up (False); `shed`: messages shed so far, per topic."""
        if queue_size < 1:
            raise ValueError("queue_size must be at least 1")
        if not 0 < flush_interval_s <= 1.0:
            raise ValueError("flush_interval_s must be in (0, 1] (sessions are flushed at least once a second)")
        self.path = Path(path)
        self.queue_size = queue_size
        self.flush_interval_s = flush_interval_s
        self._writer = McapSessionWriter(
            self.path, metadata, chunk_size=chunk_size, fsync=fsync, attachments=attachments
        )
        self._queue: deque = deque()  # (monotonic ns when queued, message); the writer pops from the left
        self.lag_budget_ns = int(lag_budget_s * 1e9) if lag_budget_s is not None else None
        self._on_behind = on_behind
        self._behind_state = 0  # 0: on time; 1: behind (log() sheds), not told yet; 2: behind, told
        self._max_lag_ns = 0
        self.priority = ""  # the writer thread's nice value once it runs, or why it could not be raised
        self._lock = threading.Lock()
        self._stats: dict[str, StreamStats] = {}
        self._errors: dict[str, str] = {}
        self._max_depth = 0
        self._accepting = True
        self._failure: BaseException | None = None
        self._on_failure = on_failure
        self._thread: threading.Thread | None = None
        self._cpu_s = 0.0
        self._t_start: float | None = None
        self._summary: RecordingSummary | None = None

    # --- producer side (any thread) ---

    def log(self, msg: Logged) -> bool:
        """Queue a message for writing; False when it was dropped (queue full, or recorder closed)."""
        with self._lock:
            st = self._stats.get(msg.topic)
            if st is None:
                st = self._stats[msg.topic] = StreamStats()
            st.received += 1
            q = self._queue
            depth = len(q)
            if depth >= self.queue_size or not self._accepting:
                st.dropped += 1
                return False
            now = time.monotonic_ns()
            try:  # the writer pops without this lock: the queue may have emptied since its length was read
                lag_ns = now - q[0][0] if depth else 0
            except IndexError:
                lag_ns = 0
            if lag_ns > self._max_lag_ns:
                self._max_lag_ns = lag_ns
            if self.lag_budget_ns is not None and self._sheds(msg, lag_ns):
                st.dropped += 1
                st.shed += 1
                return False
            q.append((now, msg))
            if depth >= self._max_depth:
                self._max_depth = depth + 1
            return True

    def _sheds(self, msg: Logged, lag_ns: int) -> bool:
        """Whether a new message waits behind a queue this old for nothing: the least valuable go first."""
        if lag_ns <= self.lag_budget_ns:
            return False
        if self._behind_state == 0:
            self._behind_state = 1
        if isinstance(msg.payload, (ImageSample, DepthSample)):  # camera frames, colour and depth
            return True
        return lag_ns > 2 * self.lag_budget_ns and not isinstance(msg.payload, Event) \
            and not msg.topic.startswith(COMMAND_PREFIX)

    @property
    def lag_s(self) -> float:
        """How long the oldest queued message has waited (0: nothing queued)."""
        try:
            return max(0, time.monotonic_ns() - self._queue[0][0]) / 1e9
        except IndexError:
            return 0.0

    @property
    def max_lag_s(self) -> float:
        return self._max_lag_ns / 1e9

    def stats(self) -> dict[str, StreamStats]:
        """A snapshot of the per-topic counters."""
        with self._lock:
            return {t: replace(s) for t, s in self._stats.items()}

    @property
    def writer_cpu_s(self) -> float:
        """CPU seconds used by the writer thread so far (updated at every flush)."""
        return self._cpu_s

    @property
    def max_queue_depth(self) -> int:
        return self._max_depth

    @property
    def failure(self) -> BaseException | None:
        """The I/O error that stopped the writer, if any (the file is then left for `teleprev recover`)."""
        return self._failure

    # --- lifecycle ---

    def start(self) -> Recorder:
        if self._thread is not None:
            raise RuntimeError("recorder already started")
        self._t_start = time.monotonic()
        self._thread = threading.Thread(target=self._run, name="teleprev-recorder", daemon=True)
        self._thread.start()
        return self

    def close(self, extra_metadata: dict[str, dict[str, str]] | None = None) -> RecordingSummary:
        """Stop accepting messages, write everything queued, the counters and `extra_metadata`, and
        complete the file. Raises SessionError if the writer failed (what it flushed stays readable
        with `teleprev recover`)."""
        if self._summary is not None:
            return self._summary
        for name, rec in (extra_metadata or {}).items():
            check_metadata(name, rec)  # before stopping anything: a bad record must not cost the file
        with self._lock:
            self._accepting = False
        if self._thread is None:
            self.start()
        self._queue.append((0, _STOP))
        self._thread.join()
        if self._failure is None:
            try:
                self._writer.flush()  # the last chunk first, so the counters follow every message
                for name, rec in (extra_metadata or {}).items():
                    self._writer.add_metadata(name, rec)
                self._writer.add_metadata(RECORDER_RECORD, self._counters_record())
                self._writer.close()
            except OSError as exc:
                self._failure = exc
        if self._failure is not None:
            self._writer.abort()
            raise SessionError(f"recording failed: {describe_os_error(self._failure)}; what was flushed is kept: "
                               f"run `teleprev recover {self.path}`", str(self.path))
        with self._lock:
            streams = {t: replace(s) for t, s in self._stats.items()}
        try:
            size = self.path.stat().st_size
        except FileNotFoundError:  # the writes went to a file someone unlinked: nothing is left to recover
            raise SessionError("the session file, or its folder, was deleted while recording; the recording "
                               "is lost", str(self.path)) from None
        self._summary = RecordingSummary(
            self.path, streams, time.monotonic() - self._t_start, self._cpu_s, self._max_depth,
            size, [f"{t}: {m}" for t, m in self._errors.items()], self.max_lag_s,
        )
        return self._summary

    def __enter__(self) -> Recorder:
        if self._thread is None:
            self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _counters_record(self) -> dict[str, str]:
        with self._lock:
            rec = {topic: s.as_json() for topic, s in sorted(self._stats.items())}
        rec.update({
            "queue_size": str(self.queue_size),
            "flush_interval_s": str(self.flush_interval_s),
            "max_queue_depth": str(self._max_depth),
            "lag_budget_s": f"{self.lag_budget_ns / 1e9:g}" if self.lag_budget_ns is not None else "none",
            "max_lag_s": f"{self.max_lag_s:.3f}",
            "writer_priority": self.priority,
            "writer_cpu_s": f"{self._cpu_s:.3f}",
            "wall_s": f"{time.monotonic() - self._t_start:.3f}",
        })
        for topic, message in self._errors.items():
            rec[f"error {topic}"] = message
        return rec

    def _fail(self, exc: OSError) -> None:
        self._failure = exc
        with self._lock:
            self._accepting = False
        if self._on_failure is not None:
            try:
                self._on_failure(exc)
            except Exception:  # a listener's own error must not hide the write failure
                pass

    # --- writer thread ---

    def _run(self) -> None:
        # The writer wakes every POLL_S and drains the queue, instead of waking for every message: a
        # thread wake-up per message costs more CPU than encoding it. Within a drain it lets go of the
        # GIL every YIELD_EVERY messages, so that producers calling log() are not held up for long.
        self.priority = raise_this_thread(WRITER_NICE, "the recorder's writer")
        writer, pop, stats = self._writer, self._queue.popleft, self._stats
        interval = self.flush_interval_s
        next_flush = time.monotonic() + interval
        sleep, monotonic = time.sleep, time.monotonic
        try:
            while True:
                stop = False
                n = 0
                while True:
                    try:
                        _, msg = pop()
                    except IndexError:
                        break
                    if msg is _STOP:
                        stop = True
                        break
                    try:
                        size = writer.write(msg)
                    except (ValueError, TypeError, OverflowError) as exc:
                        st = stats[msg.topic]
                        st.errors += 1
                        self._errors.setdefault(msg.topic, f"{type(exc).__name__}: {exc}")
                    else:
                        st = stats[msg.topic]
                        st.written += 1
                        st.bytes += size
                    n += 1
                    if n % YIELD_EVERY == 0:
                        sleep(0)
                    if n % 256 == 0 and monotonic() >= next_flush:
                        break  # a long backlog still gets flushed on time
                if stop:
                    break
                self._tell_lag()
                now = monotonic()
                if now >= next_flush:
                    writer.flush()
                    self._cpu_s = time.thread_time()
                    next_flush = now + interval
                elif n == 0 or n % 256:
                    sleep(min(POLL_S, max(0.0, next_flush - now)))
        except OSError as exc:
            self._fail(exc)
        finally:
            self._cpu_s = time.thread_time()

    def _tell_lag(self) -> None:
        """After a drain: tell the session when the writer has fallen behind (log() has started shedding),
        and when it has caught up (the queue younger than half the budget again)."""
        if self._behind_state == 1:
            self._behind_state = 2
            self._behind(True)
        elif self._behind_state == 2 and self.lag_s * 2e9 < self.lag_budget_ns:
            self._behind_state = 0
            self._behind(False)

    def _behind(self, behind: bool) -> None:
        if self._on_behind is None:
            return
        with self._lock:
            shed = {t: s.shed for t, s in self._stats.items() if s.shed}
        try:
            self._on_behind(behind, self.max_lag_s if behind else self.lag_s, shed)
        except Exception:  # a listener's own error must not stop the recording
            pass
