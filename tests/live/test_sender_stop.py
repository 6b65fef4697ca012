"""A session's end stops the command sender while the session loop may still be sending it an update: the
update must either go through or be refused, never meet a closed (or reused) descriptor."""

from __future__ import annotations

import os
import threading

from teleprev.clock import SessionClock
from teleprev.live.core import sender as sender_module
from teleprev.live.core.sender import CommandSender


class StillPlanner:
    """The planner side of the sender: adopts anything, sends nothing."""

    def adopt(self, update) -> None:
        pass

    def tick(self, t_ns: int):
        return None


def test_stop_inside_a_send_neither_raises_nor_writes_to_a_closed_pipe(monkeypatch):
    sender = CommandSender(StillPlanner(), SessionClock(), rate_hz=100.0).start()
    entered, stopped = threading.Event(), threading.Event()
    real_write = os.write
    outcome: dict = {}

    def slow_write(fd, data):
        if threading.current_thread().name == "session-loop" and not entered.is_set():
            entered.set()
            stopped.wait(0.5)  # without a shared lock, stop() closes the pipe right here
        return real_write(fd, data)

    monkeypatch.setattr(sender_module.os, "write", slow_write)

    def loop():
        try:
            outcome["sent"] = sender.send("an update")
        except OSError as exc:
            outcome["error"] = exc

    looper = threading.Thread(target=loop, name="session-loop")
    looper.start()
    assert entered.wait(5.0)
    stopper = threading.Thread(target=lambda: (sender.stop(), stopped.set()))
    stopper.start()
    looper.join(5.0)
    stopper.join(5.0)
    assert "error" not in outcome, f"send() met the closed pipe: {outcome.get('error')}"
    assert outcome["sent"] is True
    assert sender.pid is None
    assert sender.send("after the stop") is False
