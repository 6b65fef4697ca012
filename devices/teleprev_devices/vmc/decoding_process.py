"""The VMC decoding process: reads the receiver's socket and decodes each datagram at real-time priority,
outside the session process, and writes what it decoded to a pipe the session's receiver reads.

    python -m teleprev_devices.vmc.decoding_process SOCKET_FD PIPE_FD CLOCK_OFFSET_NS [ALLOW ...]

Why a process (issue 42, bench/input_age.py): python-osc takes 1-3 ms of interpreter time per whole-skeleton
datagram, 12-40 % of a core at 120 Hz, all of it under the session's interpreter lock; and a receiving
thread at nice -10 still waits for a CPU whenever other terminal sessions' work fills the machine (Linux
shares the CPUs between sessions first: beside 4 busy processes of another session a 120 Hz glove's
datagrams waited in the socket 103 ms at p95). This process asks for SCHED_FIFO (INPUT_PRIORITY: above every ordinary
process, below every other real-time one: it decodes input, it moves nothing), where no ordinary process
delays it, and without it takes the loop's nice -10. It ignores the terminal's signals (the session closes
it) and ends when the session does: its pipe breaks, or (a quiet socket) it sees its parent gone. (Not PR_SET_PDEATHSIG,
which fires when the thread that started it ends: a device's runner thread may end before the session.)
What it writes: devices/vmc/records.py.
"""

from __future__ import annotations

import dataclasses
import os
import socket
import sys
import time

from teleprev.devices import INPUT_PRIORITY, become_paced, raise_this_thread
from teleprev_devices.vmc.decode import ANCILLARY, MAX_DATAGRAM, VmcDecoder
from teleprev_devices.vmc.records import counters_record, frame_record, status_record

_PARENT_CHECK_S = 0.5  # how often a process whose socket is quiet looks whether the session is still there


def _write_all(fd: int, data: bytes) -> None:
    while data:  # (blocks while the pipe is full: the socket's buffer then fills, and its overruns are counted)
        data = data[os.write(fd, data):]


def main(argv: list[str]) -> None:
    sock_fd, pipe_fd, offset_ns = int(argv[0]), int(argv[1]), int(argv[2])
    parent = os.getppid()
    status = become_paced(INPUT_PRIORITY, die_with_parent_thread=False)
    priority = status.detail if status.realtime else \
        f"{raise_this_thread(thread='the VMC decoding process')}; {status.detail}"
    sock = socket.socket(fileno=sock_fd)
    sock.settimeout(_PARENT_CHECK_S)
    decoder = VmcDecoder(tuple(argv[3:]))
    last = dataclasses.astuple(decoder.counters)
    try:
        _write_all(pipe_fd, status_record(priority))
        while True:
            try:
                data, ancillary, _, sender = sock.recvmsg(MAX_DATAGRAM, ANCILLARY)
            except TimeoutError:
                if os.getppid() != parent:
                    return
                continue
            frame = decoder.datagram(data, ancillary, sender, offset_ns + time.monotonic_ns())
            now = dataclasses.astuple(decoder.counters)
            records = b""
            if now != last:
                records, last = counters_record(decoder.counters), now
            if frame is not None:
                records += frame_record(frame)
            if records:
                _write_all(pipe_fd, records)
    except BrokenPipeError:
        pass  # the session closed its end: done


if __name__ == "__main__":
    main(sys.argv[1:])
