"""TCP listeners for the emulators: one accept thread per port, one thread per connection, and clear
one-line errors when an address cannot be had."""

from __future__ import annotations

import errno
import random
import socket
import threading
from collections.abc import Callable

from teleprev.errors import TeleprevError


class EmulatorError(TeleprevError):
    """An emulator cannot start (an address taken, a port that needs root, no pseudo-terminal)."""


def bind_error(host: str, port: int, exc: OSError, why_this_port: str = "") -> EmulatorError:
    where = f"{host}:{port}"
    if exc.errno == errno.EACCES:
        return EmulatorError(f"cannot listen on {where}: ports below 1024 need root{why_this_port}; run as root, or "
                             f"allow it once with `sysctl net.ipv4.ip_unprivileged_port_start={port}`")
    if exc.errno == errno.EADDRINUSE:
        return EmulatorError(f"cannot listen on {where}: it is taken (another emulator, or a controller on this "
                             "machine); pick another loopback address, e.g. --host 127.0.0.2")
    if exc.errno == errno.EADDRNOTAVAIL:
        return EmulatorError(f"cannot listen on {where}: {host} is not an address of this machine (use 127.x.y.z)")
    return EmulatorError(f"cannot listen on {where}: {exc.strerror or exc}")


def listen(host: str, port: int, why_this_port: str = "") -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise bind_error(host, port, exc, why_this_port) from None
    sock.listen(8)
    sock.settimeout(0.1)
    return sock


def free_loopback_host(ports: tuple[int, ...], tries: int = 64) -> str:
    """A 127.x.y.z address on which all of `ports` are free (the whole 127/8 block is this machine's on
    Linux), so that emulators of fixed-port devices can run side by side."""
    rng = random.Random()
    for _ in range(tries):
        host = f"127.{rng.randint(16, 250)}.{rng.randint(1, 250)}.{rng.randint(2, 250)}"
        socks = []
        try:
            for p in ports:
                socks.append(listen(host, p))
            return host
        except EmulatorError as exc:
            if "need root" in str(exc):
                raise
        finally:
            for s in socks:
                s.close()
    raise EmulatorError(f"no loopback address with ports {ports} free after {tries} tries")


class Listener:
    """Accepts connections on one port and runs `serve(conn)` for each on its own thread."""

    def __init__(self, sock: socket.socket, serve: Callable[[socket.socket], None], name: str):
        self.sock = sock
        self.serve = serve
        self.name = name
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.connections: set[socket.socket] = set()
        self.accepted = 0
        self._thread = threading.Thread(target=self._accept, name=f"emulator-{name}", daemon=True)

    def start(self) -> Listener:
        self._thread.start()
        return self

    def _accept(self) -> None:
        while not self._stop.is_set():
            try:
                conn, _ = self.sock.accept()
            except (TimeoutError, BlockingIOError):
                continue
            except OSError:
                return
            conn.settimeout(0.1)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self.connections.add(conn)
                self.accepted += 1
            threading.Thread(target=self._run, args=(conn,), name=f"emulator-{self.name}-conn", daemon=True).start()

    def _run(self, conn: socket.socket) -> None:
        try:
            self.serve(conn)
        except OSError:
            pass
        finally:
            self.drop(conn)

    def drop(self, conn: socket.socket) -> None:
        with self._lock:
            self.connections.discard(conn)
        try:
            conn.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        conn.close()

    def drop_all(self) -> int:
        with self._lock:
            conns = list(self.connections)
        for c in conns:
            self.drop(c)
        return len(conns)

    @property
    def stopped(self) -> bool:
        return self._stop.is_set()

    def stop(self) -> None:
        self._stop.set()
        self.sock.close()
        self.drop_all()
        self._thread.join(2.0)
