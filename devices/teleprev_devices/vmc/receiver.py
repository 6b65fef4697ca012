"""One UDP socket per (host, port) receiving VMC (OSC) datagrams, shared by the plugins that listen there.

The socket is read by a decoding process of its own (devices/vmc/decoding_process.py: at real-time priority, out of
the session's interpreter lock), which hands each datagram to a VmcDecoder (devices/vmc/decode.py: what a
datagram means, and the counters of what was skipped) and writes each Frame it makes to a pipe. Here a
thread at the session loop's priority reads that pipe, keeps the skeleton and the counters, and hands each
subscriber every Frame. Nothing a datagram does ends the decoding process; a process that ends anyway (or
cannot start) fails the receiver, and its devices' runners reopen it.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading

from teleprev.devices import DeviceError, DeviceStartError, SessionClock, describe_exception, raise_this_thread
from teleprev_devices.fanout import Fanout
from teleprev_devices.fanout import acquire as acquire_shared
from teleprev_devices.fanout import release as release_shared
from teleprev_devices.vmc.decode import SO_RXQ_OVFL, BonePose, Counters, Frame
from teleprev_devices.vmc.records import COUNTERS, FRAME, STATUS, read_records

__all__ = ["BonePose", "Frame", "VmcReceiver", "acquire", "release"]

_PIPE_BYTES = 1 << 20  # the decoding process's pipe (F_SETPIPE_SZ where Linux allows): seconds of frames
# How long opening waits for the decoding process to read the socket (it starts in about 0.5 s; a loaded
# machine takes longer). Until then datagrams wait in the socket, and their receive times would be late.
START_TIMEOUT_S = 20.0


class VmcReceiver:
    def __init__(self, host: str, port: int, clock: SessionClock, allow: tuple[str, ...] = (),
                 receive_buffer_kb: int = 1024):
        """`allow`: the sender addresses or networks ("192.168.1.7", "10.0.0.0/24") accepted; empty: any.
        `receive_buffer_kb`: the socket's receive buffer asked for (the kernel caps it at
        net.core.rmem_max): what a sender may get ahead of the decoding process before datagrams are lost."""
        self.host, self.port, self.clock = host, port, clock
        self.allow = tuple(allow)
        self.counters = Counters()  # the decoding process's, as it last reported them
        self.where = f"VMC receiver {self.host}:{self.port}"
        self.fanout: Fanout[Frame] = Fanout(self.where)
        self.priority = ""  # the decoding process's scheduling once it reports it, or why it is not real-time
        self.reading_priority = ""  # the pipe's reading thread's nice value once it runs
        self._bones: dict[str, BonePose] = {}
        self._stop = threading.Event()
        self._reading = threading.Event()  # the decoding process reads the socket (it said its priority)
        sock = _bind(host, port, receive_buffer_kb, self.where)
        self._pipe, write_end = os.pipe()
        try:
            import fcntl

            fcntl.fcntl(write_end, 1031, _PIPE_BYTES)  # F_SETPIPE_SZ
        except (OSError, AttributeError):
            pass
        try:
            self._process = subprocess.Popen(
                [sys.executable, "-m", "teleprev_devices.vmc.decoding_process", str(sock.fileno()), str(write_end),
                 str(clock.from_monotonic(0)), *self.allow],
                pass_fds=(sock.fileno(), write_end), stdin=subprocess.DEVNULL,
                env={**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)})
        except OSError as exc:
            os.close(self._pipe)
            raise DeviceStartError(f"cannot start the VMC decoding process ({describe_exception(exc)})",
                                   self.where) from None
        finally:
            os.close(write_end)  # the process holds the socket and the pipe's write end now
            sock.close()
        self._thread = threading.Thread(target=self._run, name=f"vmc-{self.port}", daemon=True)
        self._thread.start()
        self._reading.wait(START_TIMEOUT_S)
        if not self._reading.is_set() or self.fanout.failure:
            self.close()
            raise DeviceError(self.fanout.failure or f"the VMC decoding process did not start in {START_TIMEOUT_S:g} s",
                              self.where)

    def close(self) -> None:
        self._stop.set()
        self._process.kill()  # (it ignores the terminal's signals) its end closes: the reading thread returns
        self._process.wait()
        self._thread.join(1.0)
        os.close(self._pipe)

    # ---- the pipe's reading thread ---------------------------------------------------------------
    def _run(self) -> None:
        # At the session loop's priority: frames wait in the pipe while this thread waits for a CPU.
        self.reading_priority = raise_this_thread(thread=self.where)
        buffer = b""
        try:
            while True:
                chunk = os.read(self._pipe, 1 << 16)
                if not chunk:
                    if not self._stop.is_set():
                        self.fanout.fail(f"the VMC decoding process ended (exit status {self._process.wait()})")
                    self._reading.set()
                    return
                records, buffer = read_records(buffer + chunk)
                for kind, value in records:
                    if kind == FRAME:
                        self._bones.update(value.updated)
                        self.fanout.publish(Frame(value.receive_ns, value.stamp_ns, frozenset(value.updated),
                                                  dict(self._bones)))
                    elif kind == COUNTERS:
                        self.counters = value
                    elif kind == STATUS:
                        self.priority = value
                        self._reading.set()
        except BaseException as exc:  # a bug here: the devices must hear of it (they raise, the runner reopens)
            self.fanout.fail(f"receiver thread ended: {describe_exception(exc)}")
            raise


def _bind(host: str, port: int, receive_buffer_kb: int, where: str) -> socket.socket:
    """The receiving socket, bound here so that a port in use is said at once, with its overrun count on."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise DeviceStartError(f"cannot listen on UDP {host}:{port} ({exc.strerror or exc}); "
                               "is another program using the port?", where) from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_kb * 1024)
    except OSError:
        pass  # the system's default buffer then; overruns are still counted
    if SO_RXQ_OVFL is not None:
        try:
            sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
        except OSError:
            pass  # no overrun count here; sequence gaps still show what went missing
    return sock


def acquire(shared: dict, host: str, port: int, clock: SessionClock, allow: tuple[str, ...] = ()) -> VmcReceiver:
    """The receiver for (host, port), opened by the first plugin that asks (kept in context.receivers)."""
    def conflict(receiver: VmcReceiver) -> str:
        if receiver.allow == tuple(allow):
            return ""
        return (f"the devices on UDP {host}:{port} share one socket but allow different senders "
                f"({list(receiver.allow)} and {list(allow)}); give them the same allow list")

    return acquire_shared(shared, ("vmc", host, port), lambda: VmcReceiver(host, port, clock, allow), conflict)


def release(shared: dict, receiver: VmcReceiver) -> None:
    """Give a receiver back; the last plugin to do so closes the socket."""
    release_shared(shared, ("vmc", receiver.host, receiver.port), receiver)
