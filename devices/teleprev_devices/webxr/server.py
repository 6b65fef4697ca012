"""The XR page's server: HTTPS for the page, a WebSocket for its frames, shared by the plugins on one
address (webxr.glove and webxr.suit read the same frames).

The page (page/index.html, page/xr.js) sends every XR frame as one binary message (wire.py) and the
operator's actions as JSON text ({"type": "action", "action": "toggle_mode"}); the server answers with
the session's status four times a second, which the page shows in the headset. One page drives at a
time: a newer connection takes over and the older one is closed, so a reloaded tab cannot interleave
frames with its predecessor's.

Frame times come from the page's clock and are mapped onto the session clock by ClockSync, as the VMC
receiver does: outliers are counted (`clock_outliers`) and mapped with the current offset. Each connection
has its own ClockSync (a reloaded page has a new clock origin). Nothing a
page sends can stop the server: malformed messages, non-finite values, and unknown actions are counted
and skipped. Off this machine (host other than 127.0.0.1) every request must carry the pairing token
(`?token=`), and those that do not are refused and counted (`refused_connections`).
"""

from __future__ import annotations

import asyncio
import hmac
import json
import ssl
import threading
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from teleprev.devices import (
    GESTURE,
    ClockSync,
    DeviceError,
    DeviceStartError,
    OperatorLink,
    SessionClock,
    describe_exception,
    raise_this_thread,
)
from teleprev_devices.fanout import Fanout
from teleprev_devices.fanout import acquire as acquire_shared
from teleprev_devices.fanout import release as release_shared
from teleprev_devices.webxr import certificate, wire

PAGE_DIR = Path(__file__).parent / "page"
PAGE_FILES = {
    "/": ("index.html", "text/html; charset=utf-8"),
    "/index.html": ("index.html", "text/html; charset=utf-8"),
    "/xr.js": ("xr.js", "text/javascript; charset=utf-8"),
}
SOCKET_PATH = "/ws"
STATUS_PERIOD_S = 0.25
LOOPBACK = "127.0.0.1"


@dataclass(frozen=True, slots=True)
class Frame:
    receive_ns: int
    stamp_ns: int  # the frame's time on the session clock
    xr: wire.XrFrame


@dataclass
class Counters:
    frames: int = 0
    connections: int = 0
    malformed_messages: int = 0  # not an XR frame, not JSON, or an unknown action
    non_finite: int = 0  # a frame with NaN or infinity in a tracked part
    failed_messages: int = 0  # messages whose handling raised anything else (counted, skipped)
    refused_connections: int = 0  # requests without the pairing token
    oversize_messages: int = 0  # connections closed (1009) for a message over MAX_MESSAGE bytes
    taken_over_pages: int = 0  # connections closed (4000) because another page connected
    lost_sequence_gaps: int = 0  # frames missing from the page's sequence numbers
    clock_outliers: int = 0
    actions: int = 0

    def errors(self) -> dict[str, int]:
        return {"malformed_messages": self.malformed_messages, "non_finite": self.non_finite,
                "failed_messages": self.failed_messages, "refused_connections": self.refused_connections,
                "oversize_messages": self.oversize_messages, "taken_over_pages": self.taken_over_pages,
                "lost_sequence_gaps": self.lost_sequence_gaps, "clock_outliers": self.clock_outliers}


@dataclass
class _Page:
    connection: object
    sync: ClockSync = field(default_factory=ClockSync)
    last_seq: int | None = None
    agent: str = ""
    session: str = ""  # the XR session the page runs ("immersive-ar", "immersive-vr", or "" before one)


# Every refusal of a page is counted, and so recorded as a device event (the runner's "skipped" events):
# a request without the token, a message too big (the server closes with 1009), a page another replaced.
MAX_MESSAGE = 64 * 1024  # bytes: a frame is about 2 KiB
CLOSE_TOO_BIG, CLOSE_TAKEN_OVER = 1009, 4000
_CANNOT_LISTEN = "cannot listen on"  # a start failure: the port is taken, or not this program's to open


class XrServer:
    def __init__(self, host: str, port: int, clock: SessionClock, cert_dir: Path, hooks: OperatorLink):
        self.host, self.clock, self.hooks = host, clock, hooks
        self.token_required = host != LOOPBACK
        self.where = f"WebXR server {host}:{port}"
        self.fanout: Fanout[Frame] = Fanout(self.where)
        self.counters = Counters()
        self._addresses = _addresses(host)
        try:
            self.credentials = certificate.ensure(cert_dir, self._addresses)
        except OSError as exc:
            raise DeviceStartError(f"cannot keep the page's certificate in {cert_dir} ({exc.strerror or exc}); "
                                   "set cert_dir to a folder you can write", self.where) from None
        self._page: _Page | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stopped: asyncio.Event | None = None
        started = threading.Event()
        failure: list[str] = []
        self.port = port
        self.priority = ""  # the server thread's nice value once it runs, or why it could not be raised
        self._thread = threading.Thread(
            target=self._run, args=(port, started, failure), name=f"webxr-{port}", daemon=True
        )
        self._thread.start()
        started.wait(10.0)  # (set when serving, or when it could not)
        if failure or not started.is_set():
            self._thread.join(1.0)
            if failure and failure[0].startswith(_CANNOT_LISTEN):
                raise DeviceStartError(failure[0], self.where)
            raise DeviceError(failure[0] if failure else "the server did not start within 10 s", self.where)
        self.where = f"WebXR server {host}:{self.port}"
        self.fanout.where = self.where

    # ---- what the plugins and the CLI read ---------------------------------------------------------
    def urls(self) -> list[str]:
        """The page's address(es): one per address the server is reached at, with the token when needed."""
        query = f"?token={self.credentials.token}" if self.token_required else ""
        return [f"https://{a}:{self.port}/{query}" for a in self._addresses]

    def close(self) -> None:
        loop, stopped = self._loop, self._stopped
        if loop is not None and stopped is not None and not loop.is_closed():
            try:
                loop.call_soon_threadsafe(stopped.set)
            except RuntimeError:  # the loop has just ended
                pass
        self._thread.join(3.0)

    # ---- the server thread -----------------------------------------------------------------------
    def _run(self, port: int, started: threading.Event, failure: list[str]) -> None:
        # At the session loop's priority: the page's frames wait in the socket while this thread waits for a CPU.
        self.priority = raise_this_thread(thread=self.where)
        try:
            asyncio.run(self._serve(port, started, failure))
        except BaseException as exc:  # a bug here: the devices must hear of it (they raise, the runner reopens)
            if started.is_set():
                self.fanout.fail(f"server thread ended: {describe_exception(exc)}")
            else:
                failure.append(describe_exception(exc))
                started.set()

    async def _serve(self, port: int, started: threading.Event, failure: list[str]) -> None:
        from websockets.asyncio.server import serve

        context = ssl.SSLContext(ssl.PROTOCOL_TLS_SERVER)
        context.load_cert_chain(self.credentials.cert, self.credentials.key)
        self._loop = asyncio.get_running_loop()
        self._stopped = asyncio.Event()
        try:
            server = await serve(self._connection, self.host, port, ssl=context, process_request=self._request,
                                 max_size=MAX_MESSAGE, compression=None, ping_interval=5, ping_timeout=10)
        except OSError as exc:
            failure.append(
                f"{_CANNOT_LISTEN} {self.host}:{port} ({exc.strerror or exc}); is another program using the port?"
            )
            started.set()
            return
        async with server:
            self.port = server.sockets[0].getsockname()[1]
            started.set()
            status = asyncio.create_task(self._send_status())
            await self._stopped.wait()
            status.cancel()

    def _request(self, connection, request):
        """Serve the page's files; let a WebSocket to SOCKET_PATH through; refuse what lacks the token."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        url = urllib.parse.urlsplit(request.path)
        if self.token_required:
            given = urllib.parse.parse_qs(url.query).get("token", [""])[0]
            if not hmac.compare_digest(given.encode(), self.credentials.token.encode()):
                self.counters.refused_connections += 1
                return connection.respond(
                    403, "this page needs the pairing token teleprev printed (its URL's ?token=...)\n"
                )
        if url.path == SOCKET_PATH:
            return None
        if url.path not in PAGE_FILES:
            return connection.respond(404, "not found\n")
        name, media = PAGE_FILES[url.path]
        body = (PAGE_DIR / name).read_bytes()
        return Response(200, "OK", Headers([("Content-Type", media), ("Content-Length", str(len(body))),
                                            ("Cache-Control", "no-store")]), body)

    async def _connection(self, connection) -> None:
        from websockets.exceptions import ConnectionClosed

        page = _Page(connection)
        old, self._page = self._page, page
        self.counters.connections += 1
        if old is not None:
            self.counters.taken_over_pages += 1
            await old.connection.close(CLOSE_TAKEN_OVER, "another page took over")
        try:
            async for message in connection:
                if self._page is not page:
                    break
                try:
                    if isinstance(message, bytes):
                        self._frame(page, message)
                    else:
                        await self._text(page, message)
                except ConnectionClosed:
                    break
                except Exception:  # whatever a message does, the next one is read
                    self.counters.failed_messages += 1
        except ConnectionClosed as exc:  # the connection broke (the page reconnects), or was refused
            if exc.sent is not None and exc.sent.code == CLOSE_TOO_BIG:
                self.counters.oversize_messages += 1
        except Exception:  # the connection broke: the page reconnects
            pass
        finally:
            if self._page is page:
                self._page = None

    def _frame(self, page: _Page, data: bytes) -> None:
        receive_ns = self.clock.now_ns()
        c = self.counters
        try:
            xr = wire.unpack(data)
        except wire.WireError:
            c.malformed_messages += 1
            return
        if not all(np.all(np.isfinite(p)) for p in (xr.head, xr.left, xr.right) if p is not None):
            c.non_finite += 1
            return
        if page.last_seq is not None and xr.seq > page.last_seq + 1:
            c.lost_sequence_gaps += xr.seq - page.last_seq - 1
        page.last_seq = xr.seq
        before = page.sync.rejected
        stamp = page.sync.observe(int(round(xr.time_ms * 1e6)), receive_ns)
        c.clock_outliers += page.sync.rejected - before
        c.frames += 1
        self.fanout.publish(Frame(receive_ns, stamp, xr))

    async def _text(self, page: _Page, text: str) -> None:
        try:
            message = json.loads(text)
            kind = message["type"]
        except (ValueError, KeyError, TypeError):
            self.counters.malformed_messages += 1
            return
        if kind == "hello":
            page.agent = str(message.get("agent", ""))[:200]
            page.session = str(message.get("session", ""))[:40]
        elif kind == "action":
            action = str(message.get("action", ""))
            via = GESTURE if message.get("via") == GESTURE else ""
            act = self.hooks.act
            refused = act(action, via) if act is not None else "no session is recording (teleprev record starts one)"
            if refused == "unknown":
                self.counters.malformed_messages += 1
            else:
                self.counters.actions += 1
            await page.connection.send(json.dumps({"type": "ack", "action": action, "refused": refused}))
        else:
            self.counters.malformed_messages += 1

    async def _send_status(self) -> None:
        while True:
            await asyncio.sleep(STATUS_PERIOD_S)
            page = self._page
            if page is None:
                continue
            status = self.hooks.status() if self.hooks.status is not None else {"recording": False}
            status = {"type": "status", "frames": self.counters.frames,
                      "refused_connections": self.counters.refused_connections, **status}
            try:
                await page.connection.send(json.dumps(status))
            except Exception:  # closed meanwhile: the page reconnects
                pass


def _addresses(host: str) -> list[str]:
    """The addresses a page reaches the server at: the host itself, or this machine's for 0.0.0.0."""
    if host != "0.0.0.0":
        return [host]
    import socket

    found = [LOOPBACK]
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.connect(("10.255.255.255", 1))  # no packet is sent: this asks which interface would route it
            address = s.getsockname()[0]
        if address != "0.0.0.0" and address not in found:
            found.insert(0, address)
    except OSError:
        pass
    return found


def acquire(shared: dict, host: str, port: int, clock: SessionClock, cert_dir: Path, hooks: OperatorLink) -> XrServer:
    """The server for (host, port), started by the first plugin that asks (kept in context.receivers)."""
    def conflict(server: XrServer) -> str:
        return "" if server.credentials.cert.parent == Path(cert_dir) else (
            f"the devices on {host}:{port} share one server but name different cert_dir; give them the same one")

    return acquire_shared(shared, ("webxr", host, port), lambda: XrServer(host, port, clock, cert_dir, hooks), conflict)


def release(shared: dict, server: XrServer, port: int) -> None:
    release_shared(shared, ("webxr", server.host, port), server)
