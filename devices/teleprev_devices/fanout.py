"""One receiving socket shared by several device plugins: each plugin subscribes and reads every item in
order (a bounded queue each), and the plugins on one address share the receiver through the context.

    receiver = acquire(context.shared, ("vmc", host, port), lambda: VmcReceiver(...))
    sub = receiver.fanout.subscribe(); receiver.fanout.wait(sub, 0.1); release(context.shared, key, receiver)

Used by the VMC receiver (one UDP port: a suit and a glove) and the WebXR server (one page: the glove's
hands and the suit's wrist).
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Callable, Generic, Protocol, TypeVar

from teleprev.devices import DeviceError

T = TypeVar("T")
QUEUE = 256  # items kept per subscriber that is not reading fast enough


class Subscription(Generic[T]):
    def __init__(self, size: int = QUEUE):
        self.items: deque[T] = deque(maxlen=size)
        self.ready = threading.Condition()
        self.overflow = 0  # items pushed out of the queue before the device read them


class Fanout(Generic[T]):
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


def acquire(shared: dict, key: tuple, open_: Callable[[], R], conflict: Callable[[R], str] = lambda r: "") -> R:
    """The receiver under `key` in context.shared, opened by the first plugin that asks (a failed one is
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
