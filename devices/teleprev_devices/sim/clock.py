"""Simulated device clocks and transport, and the ground truth the sync benchmark compares against.

A real device stamps a sample with its own clock (its own epoch, running a few ppm fast or slow) and the
sample reaches the host after a transport delay (a fixed minimum plus jitter). A sim device does the
same: `DeviceClock` turns a true session time into the device's stamp, `Transport` draws the delay, and
the device converts the stamp back with `ClockSync` exactly as a hardware plugin would. `TruthLog`
keeps, for every emitted sample, the true acquisition time next to the stamp that was handed on, so
`sync_err` (recorded stamp minus true time) can be measured from a recording.
"""

from __future__ import annotations

import csv
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from teleprev.devices import ConfigError, SessionClock


class DeviceClock:
    """A device's own clock: `offset_s` ahead of the session clock at its start, drifting `drift_ppm`."""

    def __init__(self, session: SessionClock, offset_s: float, drift_ppm: float):
        self._origin = session.start_ns
        self._offset_ns = int(round(offset_s * 1e9))
        self.rate = 1.0 + drift_ppm * 1e-6

    def device_ns(self, session_ns: int) -> int:
        return self._origin + self._offset_ns + int(round((session_ns - self._origin) * self.rate))

    def session_ns(self, device_ns: int) -> int:
        """The true session time of a device reading (the inverse of device_ns, to a nanosecond)."""
        return self._origin + int(round((device_ns - self._origin - self._offset_ns) / self.rate))


class Transport:
    """Delivery delay: `min_ms` always, plus jitter that is usually small (exponential, mean `jitter_ms`)
    and now and then a late packet (probability `spike_prob`, up to 10 x jitter more)."""

    def __init__(self, min_ms: float, jitter_ms: float, rng: np.random.Generator, spike_prob: float = 0.01):
        self.min_ns = int(round(min_ms * 1e6))
        self._jitter_ns = jitter_ms * 1e6
        self._spike_prob = spike_prob
        self._rng = rng
        self._batch: list[int] = []

    def _draw(self, n: int = 512) -> list[int]:
        # Drawn in batches: one generator call per few seconds instead of two per sample.
        if self._jitter_ns <= 0:
            return [self.min_ns] * n
        extra = self._rng.exponential(self._jitter_ns, n)
        spikes = self._rng.random(n) < self._spike_prob
        extra[spikes] += self._rng.uniform(0.0, 10.0 * self._jitter_ns, int(spikes.sum()))
        return (self.min_ns + extra.astype(np.int64))[::-1].tolist()

    def delay_ns(self) -> int:
        if not self._batch:
            self._batch = self._draw()
        return self._batch.pop()


@dataclass(frozen=True)
class TruthRecord:
    topic: str
    stamp_ns: int  # the stamp handed on (device time converted to the session clock)
    true_ns: int  # when the sample was really acquired, on the session clock
    device_ns: int  # the device's own stamp
    receive_ns: int  # when the host read it


class TruthLog:
    """The true acquisition time of every sample the sim devices of one rig emitted.

    Looked up by (topic, stamp_ns), the key a recorded message carries. Bounded in memory (the oldest go
    first); after `write_to(path)` every record is also appended to a CSV file (topic,stamp_ns,true_ns,
    device_ns,receive_ns) for a benchmark that reads it after the session. One per rig, shared through
    context.shared["sim.truth"] (see `shared_truth`).
    """

    def __init__(self, max_records: int = 500_000):
        self._records: OrderedDict[tuple[str, int], TruthRecord] = OrderedDict()
        self._max = max_records
        self._lock = threading.Lock()
        self._file = None
        self._writer = None
        self.path: Path | None = None

    def write_to(self, path: str | Path) -> None:
        """Also append every record to a CSV file from now on (one file per rig)."""
        path = Path(path).resolve()
        with self._lock:
            if self.path == path:
                return
            if self.path is not None:
                raise ConfigError(
                    f"sim devices of one rig must share one truth_log file (already writing {self.path})", str(path)
                )
            path.parent.mkdir(parents=True, exist_ok=True)
            self._file = path.open("a", newline="")
            self._writer = csv.writer(self._file)
            if self._file.tell() == 0:
                self._writer.writerow(["topic", "stamp_ns", "true_ns", "device_ns", "receive_ns"])
            self.path = path

    def add(self, record: TruthRecord) -> None:
        with self._lock:
            self._records[(record.topic, record.stamp_ns)] = record
            if len(self._records) > self._max:
                self._records.popitem(last=False)
            if self._writer is not None:
                self._writer.writerow(
                    [record.topic, record.stamp_ns, record.true_ns, record.device_ns, record.receive_ns]
                )

    def true_ns(self, topic: str, stamp_ns: int) -> int | None:
        with self._lock:
            rec = self._records.get((topic, stamp_ns))
        return None if rec is None else rec.true_ns

    def records(self, topic: str | None = None) -> list[TruthRecord]:
        with self._lock:
            return [r for r in self._records.values() if topic is None or r.topic == topic]

    def max_error_ns(self, topic: str | None = None) -> int:
        """Worst |stamp - true| over the records kept (0 if none)."""
        return max((abs(r.stamp_ns - r.true_ns) for r in self.records(topic)), default=0)

    def flush(self) -> None:
        with self._lock:
            if self._file is not None:
                self._file.flush()


def shared_truth(shared: dict) -> TruthLog:
    """The rig's TruthLog, created on first use."""
    from teleprev_devices.sim.shared import get_or_create

    return get_or_create(shared, "sim.truth", TruthLog)
