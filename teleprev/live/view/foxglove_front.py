"""The live Foxglove view's listening socket: it hands every connection to foxglove-sdk's server (on a private
loopback port) and accepts both names of the Foxglove WebSocket protocol. Older Foxglove Studio and Lichtblick
offer only "foxglove.websocket.v1", which foxglove-sdk answers with HTTP 400; the protocol itself is the same
under its newer name "foxglove.sdk.v1". So the handshake's Sec-WebSocket-Protocol is rewritten on the way in
and back on the way out, and everything after it is copied byte for byte.
"""

from __future__ import annotations

import socket
import threading

OLD, NEW = b"foxglove.websocket.v1", b"foxglove.sdk.v1"
_HEAD_LIMIT = 64 * 1024  # an HTTP upgrade request or response is a few hundred bytes


class SubprotocolFront:
    def __init__(self, host: str, port: int, server_port: int):
        """Listen on host:port (0: any free port) for connections to the server on 127.0.0.1:server_port.
        Raises OSError when the port cannot be had."""
        self.server_port = server_port
        self._listener = socket.create_server((host, port))
        self.port = self._listener.getsockname()[1]
        self._open: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._closed = False
        threading.Thread(target=self._accept, name="foxglove-front", daemon=True).start()

    def close(self) -> None:
        self._closed = True
        self._listener.close()
        with self._lock:
            for s in list(self._open):
                _shut(s)

    def _accept(self) -> None:
        while not self._closed:
            try:
                client, _ = self._listener.accept()
            except OSError:  # closed
                return
            threading.Thread(target=self._serve, args=(client,), name="foxglove-front-client", daemon=True).start()

    def _serve(self, client: socket.socket) -> None:
        server = None
        try:
            head, rest = _read_head(client)
            legacy = _offers_only_old(head)
            if legacy:
                head = _replace_protocol(head, OLD, NEW)
            server = socket.create_connection(("127.0.0.1", self.server_port))
            with self._lock:
                self._open.update((client, server))
            server.sendall(head + rest)
            answer, rest = _read_head(server)
            if legacy:
                answer = _replace_protocol(answer, NEW, OLD)
            client.sendall(answer + rest)
        except OSError:
            for s in (client, server):
                if s is not None:
                    _shut(s)
            return
        threading.Thread(target=_copy, args=(server, client), daemon=True).start()
        _copy(client, server)
        with self._lock:
            self._open.difference_update((client, server))


def _read_head(sock: socket.socket) -> tuple[bytes, bytes]:
    """The HTTP head (through the blank line) and whatever came after it in the same reads."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = sock.recv(4096)
        if not chunk or len(data) > _HEAD_LIMIT:
            raise OSError("the connection closed during the handshake")
        data += chunk
    end = data.index(b"\r\n\r\n") + 4
    return data[:end], data[end:]


def _protocol_lines(head: bytes) -> list[int]:
    lines = head.split(b"\r\n")
    return [k for k, line in enumerate(lines) if line.lower().startswith(b"sec-websocket-protocol:")]


def _offers_only_old(head: bytes) -> bool:
    lines = head.split(b"\r\n")
    offered = {p.strip() for k in _protocol_lines(head) for p in lines[k].split(b":", 1)[1].split(b",")}
    return OLD in offered and NEW not in offered


def _replace_protocol(head: bytes, old: bytes, new: bytes) -> bytes:
    lines = head.split(b"\r\n")
    for k in _protocol_lines(head):
        name, value = lines[k].split(b":", 1)
        lines[k] = name + b": " + b", ".join(new if p.strip() == old else p.strip() for p in value.split(b","))
    return b"\r\n".join(lines)


def _copy(src: socket.socket, dst: socket.socket) -> None:
    try:
        while True:
            data = src.recv(65536)
            if not data:
                break
            dst.sendall(data)
    except OSError:
        pass
    finally:
        _shut(dst)
        _shut(src)


def _shut(sock: socket.socket) -> None:
    try:
        sock.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    sock.close()
