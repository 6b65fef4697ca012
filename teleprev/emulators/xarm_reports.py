"""The emulated xArm's report ports: the controller pushes its state to every client, the normal (30001) and
rich (30002) reports at 5 Hz and the real-time report (30003) at 100 Hz (UFactory developer manual, report
ports; layouts in xarm_wire). A silenced connection stays open and sends nothing (the injected fault
silent_report)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from teleprev.emulators import xarm_wire as wire
from teleprev.emulators.listening import Listener

REPORT_PORTS = (wire.REPORT_NORMAL_PORT, wire.REPORT_RICH_PORT, wire.REPORT_REAL_PORT)


class ReportStreams:
    """Serves the report ports from `snapshot()`, the arm's state now."""

    def __init__(self, snapshot: Callable[[], wire.ReportState], period_s: float = wire.REPORT_PERIOD_S):
        self.snapshot = snapshot
        self.period_s = period_s
        self._lock = threading.Lock()
        self._silenced: set = set()

    def silence(self, listeners: list[Listener]) -> None:
        """The connections open now stop sending."""
        with self._lock:
            for listener in listeners:
                self._silenced.update(listener.connections)

    def _silent(self, conn) -> bool:
        with self._lock:
            return conn in self._silenced

    def packet(self, port: int) -> bytes:
        if port == wire.REPORT_REAL_PORT:
            return wire.pack_real_report(self.snapshot())
        size = wire.NORMAL_REPORT_SIZE if port == wire.REPORT_NORMAL_PORT else wire.RICH_REPORT_SIZE
        return wire.pack_report(self.snapshot(), size)

    def serve(self, conn, port: int) -> None:
        """Push reports on one connection at its port's rate until it is closed (the listener stopping
        closes it)."""
        period = wire.REAL_REPORT_PERIOD_S if port == wire.REPORT_REAL_PORT else self.period_s
        next_t = time.monotonic()
        while conn.fileno() >= 0:
            if not self._silent(conn):
                conn.sendall(self.packet(port))
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
