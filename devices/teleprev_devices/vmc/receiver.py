"""One UDP socket per (host, port) receiving VMC (OSC) datagrams, shared by the plugins that listen there.

The socket's receiving thread hands each datagram to a VmcDecoder (devices/vmc/decode.py: what a datagram
means, and the counters of what was skipped) and each subscriber every Frame it makes. The receiving
thread never ends on input.
"""

from __future__ import annotations

import socket
import threading

from teleprev.devices import DeviceStartError, SessionClock, describe_exception, raise_this_thread
from teleprev_devices.fanout import Fanout
from teleprev_devices.fanout import acquire as acquire_shared
from teleprev_devices.fanout import release as release_shared
from teleprev_devices.vmc.decode import ANCILLARY, MAX_DATAGRAM, SO_RXQ_OVFL, BonePose, Frame, VmcDecoder

__all__ = ["BonePose", "Frame", "VmcReceiver", "acquire", "release"]


class VmcReceiver:
    def __init__(self, host: str, port: int, clock: SessionClock, allow: tuple[str, ...] = (),
                 receive_buffer_kb: int = 1024):
        """`allow`: the sender addresses or networks ("192.168.1.7", "10.0.0.0/24") accepted; empty: any.
        `receive_buffer_kb`: the socket's receive buffer asked for (the kernel caps it at
        net.core.rmem_max): what a sender may get ahead of the receiving thread before datagrams are lost."""
        self.host, self.port, self.clock = host, port, clock
        self.allow = tuple(allow)
        self.decoder = VmcDecoder(self.allow)
        self.counters = self.decoder.counters
        self.where = f"VMC receiver {self.host}:{self.port}"
        self.fanout: Fanout[Frame] = Fanout(self.where)
        self._stop = threading.Event()
        try:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._sock.bind((self.host, self.port))
        except OSError as exc:
            raise DeviceStartError(f"cannot listen on UDP {self.host}:{self.port} ({exc.strerror or exc}); "
                                   "is another program using the port?", self.where) from None
        try:
            self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer_kb * 1024)
        except OSError:
            pass  # the system's default buffer then; overruns are still counted
        if SO_RXQ_OVFL is not None:
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
            except OSError:
                pass  # no overrun count here; sequence gaps still show what went missing
        self._sock.settimeout(0.1)
        self.priority = ""  # the receiving thread's nice value once it runs, or why it could not be raised
        self._thread = threading.Thread(target=self._run, name=f"vmc-{self.port}", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)
        self._sock.close()

    # ---- the receiving thread --------------------------------------------------------------------
    def _run(self) -> None:
        # At the session loop's priority: datagrams wait in the socket while this thread waits for a CPU.
        self.priority = raise_this_thread(thread=self.where)
        try:
            while not self._stop.is_set():
                try:
                    data, ancillary, _, sender = self._sock.recvmsg(MAX_DATAGRAM, ANCILLARY)
                except TimeoutError:
                    continue
                except OSError as exc:
                    if not self._stop.is_set():
                        self.fanout.fail(f"socket error: {describe_exception(exc)}")
                    return
                frame = self.decoder.datagram(data, ancillary, sender, self.clock.now_ns())
                if frame is not None:
                    self.fanout.publish(frame)
        except BaseException as exc:  # a bug here: the devices must hear of it (they raise, the runner reopens)
            self.fanout.fail(f"receiver thread ended: {describe_exception(exc)}")
            raise


def acquire(shared: dict, host: str, port: int, clock: SessionClock, allow: tuple[str, ...] = ()) -> VmcReceiver:
    """The receiver for (host, port), opened by the first plugin that asks (kept in context.shared)."""
    def conflict(receiver: VmcReceiver) -> str:
        if receiver.allow == tuple(allow):
            return ""
        return (f"the devices on UDP {host}:{port} share one socket but allow different senders "
                f"({list(receiver.allow)} and {list(allow)}); give them the same allow list")

    return acquire_shared(shared, ("vmc", host, port), lambda: VmcReceiver(host, port, clock, allow), conflict)


def release(shared: dict, receiver: VmcReceiver) -> None:
    """Give a receiver back; the last plugin to do so closes the socket."""
    release_shared(shared, ("vmc", receiver.host, receiver.port), receiver)
