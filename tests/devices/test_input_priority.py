"""The threads a glove's or headset's sample passes before the session loop (the socket's receiving thread,
the device's runner) run at the loop's nice value (a VMC glove's socket is read by a real-time process),
so that busy processes beside a session do not leave samples waiting in a socket or a queue while the loop
is free (bench/input_age.py measures the age this keeps off: at nice 0 beside 4 busy processes a 120 Hz
glove's samples reached the step 181-422 ms old at p95, at nice -10 40-57 ms). Root here, as in CI:
without it the threads stay where they are and say why."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

from teleprev.clock import SessionClock
from teleprev.devices import INPUT_PRIORITY, DeviceContext, DeviceRunner
from teleprev.thread_priority import LOOP_NICE
from teleprev_devices.vmc import VmcGlove
from teleprev_devices.vmc.plugins import VmcSettings
from teleprev_devices.webxr import WebXrGlove
from teleprev_devices.webxr.plugins import WebXrSettings
from tests.helpers.ports import free_port
from tests.helpers.vmc import VmcSender
from tests.helpers.wait import wait_until
from tests.helpers.xr_page import PageClient, open_hand


def _nice(tid: int) -> int:
    stat = Path(f"/proc/self/task/{tid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[16])  # field 19 of proc(5), counted after the command name


@pytest.fixture(autouse=True)
def root():
    assert os.geteuid() == 0, "this test checks the raised priority, which needs root (CI runs as root)"


def _run(device, clock):
    got = []
    runner = DeviceRunner(device, lambda sample, receive_ns: got.append(sample), clock).start()
    return runner, got


def test_a_vmc_glove_is_decoded_at_real_time_priority_and_handed_on_at_the_loops():
    """The socket is read and decoded by a process of its own at SCHED_FIFO (devices/vmc/decoding_process.py),
    the pipe it writes to and the runner at the loop's nice value."""
    clock = SessionClock()
    port = free_port()
    runner, got = _run(VmcGlove("g", VmcSettings(port=port), DeviceContext(clock)), clock)
    sender = VmcSender(port)
    try:
        wait_until(lambda: runner.connected, what="the glove opened")
        sender.start(rate_hz=120.0, seconds=0.3)
        wait_until(lambda: any(s.topic == "/glove/g/hand" for s in got), what="a glove sample over UDP")
        receiver = runner.device._receiver
        assert receiver.priority == f"SCHED_FIFO priority {INPUT_PRIORITY}"
        assert os.sched_getscheduler(receiver._process.pid) == os.SCHED_FIFO
        assert os.sched_getparam(receiver._process.pid).sched_priority == INPUT_PRIORITY
        assert receiver.reading_priority == runner.priority == f"nice {LOOP_NICE}"
        assert _nice(receiver._thread.native_id) == LOOP_NICE
        assert _nice(runner._thread.native_id) == LOOP_NICE
    finally:
        sender.stop()
        runner.stop()


def test_the_xr_pages_server_and_its_glove_run_at_the_loops_priority(tmp_path):
    clock = SessionClock()
    glove = WebXrGlove("g", WebXrSettings(port=0, cert_dir=str(tmp_path / "cert")), DeviceContext(clock))
    runner, got = _run(glove, clock)
    try:
        wait_until(lambda: runner.connected, what="the page's server opened")
        server = glove._receiver
        page = PageClient(server.port)
        deadline = time.monotonic() + 5.0
        while not got and time.monotonic() < deadline:
            page.frame(right=open_hand())
            time.sleep(0.02)
        assert got, "no hand from the page"
        assert server.priority == runner.priority == f"nice {LOOP_NICE}"
        assert _nice(server._thread.native_id) == LOOP_NICE
        assert _nice(runner._thread.native_id) == LOOP_NICE
    finally:
        runner.stop()
