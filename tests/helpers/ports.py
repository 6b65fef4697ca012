"""A free port on this machine's loopback, for a test's receiver or server to listen on."""

from __future__ import annotations

import socket


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A port no socket of `kind` (UDP by default; socket.SOCK_STREAM for TCP) is bound to on 127.0.0.1 now."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_tcp_port() -> int:
    return free_port(socket.SOCK_STREAM)
