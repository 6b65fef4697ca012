"""The physics world's shared memory: how the world process and its users in other processes meet.

One block, mapped by the world process (teleprev/world/process.py), the session process and any process
forked from it (the paced sender), so an actuator reaches the world from whichever process sends its
commands. Nothing in it is pickled; every part is a fixed-size array or a length-prefixed JSON text:

    header    int64 counters: the state's seqlock, the world's time, the layout running and the one asked
              for, alive / stop flags, steps taken and how far behind the clock the world fell
    ctrl      the drives' targets, by actuator index (written by the actuators, read before each batch of steps)
    qpos qvel the world's state after the latest batch (written by the world process under the seqlock)
    info      JSON: the effector and, per joint name, its qpos and dof addresses and actuator index
    request   JSON: the layout record asked for (teleprev/world/layout.py: Layout.to_record)
    running   JSON: the layout record the world runs now
    began     JSON: how the world began running it: its time then, the robot's joint positions (at rest) and
              whether they were placed (the drives' targets reset to them) or kept from the scene before
    outcome   JSON: the task's outcome judged from the last states (teleprev/world/success.py), under its
              own seqlock
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np

MAX_CTRL = 64
MAX_STATE = 1024  # qpos and qvel entries: the robot and a task's objects (pour: 106) with room to spare
HEADER = 16
_INFO, _LAYOUT, _OUTCOME, _BEGAN = 16_384, 65_536, 8_192, 8_192

# header slots
(SEQ, TIME_NS, GENERATION, REQUESTED, ALIVE, STEPS, LATE_MAX_NS, STOP, OUTCOME_SEQ, LATE_BATCHES, PID,
 REALTIME) = range(12)


@dataclass(frozen=True)
class _Region:
    offset: int
    size: int


def _regions() -> dict[str, _Region]:
    sizes = {"header": HEADER * 8, "ctrl": MAX_CTRL * 8, "qpos": MAX_STATE * 8, "qvel": MAX_STATE * 8,
             "info": _INFO, "request": _LAYOUT, "running": _LAYOUT, "outcome": _OUTCOME, "began": _BEGAN}
    out, offset = {}, 0
    for name, size in sizes.items():
        out[name] = _Region(offset, size)
        offset += size
    return out


REGIONS = _regions()
SIZE = sum(r.size for r in REGIONS.values())


class SharedBlock:
    """Typed views of the block in one process's mapping (`buffer`: an mmap of SIZE bytes)."""

    def __init__(self, buffer):
        self.buffer = buffer

        def view(name: str, dtype) -> np.ndarray:
            r = REGIONS[name]
            return np.frombuffer(buffer, dtype=dtype, count=r.size // np.dtype(dtype).itemsize, offset=r.offset)

        self.header = view("header", np.int64)
        self.ctrl = view("ctrl", np.float64)
        self.qpos = view("qpos", np.float64)
        self.qvel = view("qvel", np.float64)
        self._bytes = {name: view(name, np.uint8) for name in ("info", "request", "running", "outcome", "began")}

    # ---- length-prefixed JSON texts -------------------------------------------------------------
    def write_json(self, name: str, value: dict) -> None:
        data = json.dumps(value).encode()
        region = self._bytes[name]
        if len(data) + 8 > len(region):
            raise ValueError(f"the world's {name} record is {len(data)} bytes, more than its {len(region) - 8}")
        region[8:8 + len(data)] = np.frombuffer(data, np.uint8)
        region[:8] = np.frombuffer(np.int64(len(data)).tobytes(), np.uint8)

    def read_json(self, name: str) -> dict | None:
        region = self._bytes[name]
        n = int(np.frombuffer(region[:8].tobytes(), np.int64)[0])
        return json.loads(region[8:8 + n].tobytes()) if n else None

    # ---- the state, under its seqlock -------------------------------------------------------------
    def begin_write(self, slot: int = SEQ) -> None:
        self.header[slot] += 1  # odd: a write is under way

    def end_write(self, slot: int = SEQ) -> None:
        self.header[slot] += 1

    def read_consistent(self, read, slot: int = SEQ, timeout_s: float = 0.5):
        """`read()` retried until no write overlapped it (the writer holds the lock for microseconds)."""
        deadline = time.monotonic() + timeout_s
        while True:
            before = int(self.header[slot])
            if before % 2 == 0:
                value = read()
                if int(self.header[slot]) == before:
                    return value
            if time.monotonic() > deadline:
                raise TimeoutError("the physics world's shared state stayed busy (its process stalled mid-write)")
            time.sleep(0)
