"""One receiving socket shared by several device plugins: each plugin subscribes and reads every item in
order (a bounded queue each), and the plugins on one address share the receiver through the context.

    receiver = acquire(context.receivers, ("vmc", host, port), lambda: VmcReceiver(...))
    sub = receiver.fanout.subscribe(); receiver.fanout.wait(sub, 0.1); release(context.receivers, key, receiver)

Used by the VMC receiver (one UDP port: a suit and a glove) and the WebXR server (one page: the glove's
hands and the suit's wrist); FanoutDevice is their plugins' common half.
"""

from __future__ import annotations

import ipaddress
import threading
from abc import abstractmethod
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, TypeVar

from teleprev.devices import Device, DeviceContext, DeviceError, Sample

T = TypeVar("T")


@dataclass
class ListenSettings:
    """A receiver's address and the stream's pace, checked when the rig loads."""

    host: str = "127.0.0.1"  # the address to listen on; "0.0.0.0" accepts senders on other machines
    port: int = 0
    rate_hz: float = 60.0  # the sender's frame rate (for the rate display and gap detection)
    timeout_s: float = 0.0  # > 0: no frame for this long is a fault (the runner reopens the receiver); 0: only a gap

    def __post_init__(self):
        try:
            ipaddress.IPv4Address(self.host)
        except ValueError:
            raise ValueError(f"host must be an IPv4 address to listen on (e.g. 127.0.0.1), got {self.host!r}") from None
        if not 0 <= self.port <= 65535:
            raise ValueError(f"port must be 0..65535, got {self.port}")
        if not 0 < self.rate_hz <= 1000:
            raise ValueError(f"rate_hz must be in (0, 1000], got {self.rate_hz}")
        if self.timeout_s < 0:
            raise ValueError(f"timeout_s must be >= 0, got {self.timeout_s}")


QUEUE = 256  # items kept per subscriber that is not reading fast enough


class Subscription[T]:
    def __init__(self, size: int = QUEUE):
        self.items: deque[T] = deque(maxlen=size)
        self.ready = threading.Condition()
        self.overflow = 0  # items pushed out of the queue before the device read them


class Fanout[T]:
    def __init__(self, where: str):
        self.where = where
        self.failure = ""  # set when the receiver broke; subscribers then raise
        self._subs: list[Subscription[T]] = []
        self._lock = threading.Lock()

    def subscribe(self) -> Subscription[T]:
        sub: Subscription[T] = Subscription()
        with self._lock:
            self._subs.append(sub)
        return sub

    def unsubscribe(self, sub: Subscription[T]) -> int:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
            return len(self._subs)

    def publish(self, item: T) -> None:
        with self._lock:
            subs = list(self._subs)
        for sub in subs:
            with sub.ready:
                if len(sub.items) == sub.items.maxlen:
                    sub.overflow += 1  # the oldest item is pushed out unread
                sub.items.append(item)
                sub.ready.notify_all()

    def wait(self, sub: Subscription[T], timeout_s: float) -> list[T]:
        """What arrived since the last call, waiting up to timeout_s for something; DeviceError once the
        receiver has failed and nothing is left to read."""
        with sub.ready:
            if not sub.items and not self.failure:
                sub.ready.wait(timeout_s)
            items = list(sub.items)
            sub.items.clear()
        if self.failure and not items:
            raise DeviceError(self.failure, self.where)
        return items

    def fail(self, message: str) -> None:
        self.failure = message
        with self._lock:
            subs = list(self._subs)
        for sub in subs:
            with sub.ready:
                sub.ready.notify_all()


class Receiver(Protocol):
    fanout: Fanout

    def close(self) -> None: ...


R = TypeVar("R", bound=Receiver)
_SHARED_LOCK = threading.Lock()


def acquire[R: Receiver](
    shared: dict, key: tuple, open_: Callable[[], R], conflict: Callable[[R], str] = lambda r: ""
) -> R:
    """The receiver under `key` in context.receivers, opened by the first plugin that asks (a failed one is
    closed and opened again). `conflict(receiver)`: why this plugin's settings cannot share it ("" if they can)."""
    with _SHARED_LOCK:
        entry = shared.get(key)
        if entry is not None and entry[0].fanout.failure:
            entry[0].close()
            entry = None
        if entry is not None:
            why = conflict(entry[0])
            if why:
                raise DeviceError(why, entry[0].fanout.where)
        if entry is None:
            entry = shared[key] = [open_(), 0]
        entry[1] += 1
        return entry[0]


def release(shared: dict, key: tuple, receiver: Receiver) -> None:
    """Give a receiver back; the last plugin to do so closes it."""
    with _SHARED_LOCK:
        entry = shared.get(key)
        if entry is None or entry[0] is not receiver:  # a failed receiver already replaced
            receiver.close()
            return
        entry[1] -= 1
        if entry[1] <= 0:
            del shared[key]
            receiver.close()


S = TypeVar("S")


class FanoutDevice(Device[S]):
    """A plugin that reads a shared receiver: it subscribes on connect, converts every item the receiver
    fans out, and, with a `timeout_s` setting above 0, turns that long without an item into a fault."""

    def __init__(self, name: str, settings: S, context: DeviceContext):
        super().__init__(name, settings, context)
        self._receiver = None
        self._sub: Subscription | None = None
        self._last_item_ns = 0

    @abstractmethod
    def open_receiver(self) -> Receiver:
        """The shared receiver (acquire)."""

    @abstractmethod
    def close_receiver(self, receiver) -> None:
        """Give it back (release)."""

    @abstractmethod
    def convert(self, item) -> list[Sample]:
        """The samples one received item gives this device."""

    @abstractmethod
    def silence(self, seconds: float) -> str:
        """What to tell the operator when nothing came for `seconds`."""

    def connect(self) -> None:
        self._receiver = self.open_receiver()
        self._sub = self._receiver.fanout.subscribe()
        self._last_item_ns = self.context.clock.now_ns()

    def disconnect(self) -> None:
        receiver, self._receiver = self._receiver, None
        if receiver is not None:
            receiver.fanout.unsubscribe(self._sub)
            self.close_receiver(receiver)

    def counters(self) -> dict[str, int]:
        receiver, sub = self._receiver, self._sub
        if receiver is None or sub is None:
            return {}
        return {**receiver.counters.errors(), "lost_queue_overflow": sub.overflow}

    def read(self, timeout_s: float) -> list[Sample]:
        receiver = self._receiver
        if receiver is None:
            raise DeviceError("not connected", f"device {self.name!r}")
        items = receiver.fanout.wait(self._sub, timeout_s)
        out: list[Sample] = []
        for item in items:
            out.extend(self.convert(item))
        self._check_timeout(bool(items))
        return out

    def _check_timeout(self, got: bool) -> None:
        limit = self.settings.timeout_s
        if limit <= 0:
            return
        now = self.context.clock.now_ns()
        if got:
            self._last_item_ns = now
        elif now - self._last_item_ns > limit * 1e9:
            raise DeviceError(self.silence(limit), f"device {self.name!r}")
