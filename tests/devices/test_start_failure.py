"""A device that cannot start (its WebXR port taken, its certificate folder not writable, a VMC port taken)
fails at once with one line naming the device(s) and the reason: it waited out the connect timeout, then
printed the session's table, the preview-only note, one failure note per device and one error per device."""

from __future__ import annotations

import os
import pty
import re
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from teleprev.clock import SessionClock
from teleprev.devices import DeviceContext, DeviceStartError, load_plugin
from teleprev.devices.runner import DeviceRunner
from teleprev.messages import Event
from tests.helpers.faults import ROOT, TELEPREV, _env, has_traceback, run_cli
from tests.helpers.wait import wait_until

WEBXR_RIG = Path(__file__).parents[2] / "rigs" / "webxr_sim.toml"


@pytest.fixture
def port_taken(tmp_path):
    """(port, rig): the WebXR rig with its page on a port another socket listens on, for the test's length."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        rig = tmp_path / "rig.toml"
        rig.write_text(WEBXR_RIG.read_text().replace("port = 8443", f"port = {port}"))
        yield port, rig


def cannot_listen(port: int) -> str:
    """The one line a session or calibration ends with when the page's port is taken (a regular expression)."""
    return (rf"error: devices 'glove', 'suit' \(webxr.glove, webxr.suit\) cannot start: WebXR server "
            rf"127.0.0.1:{port}: cannot listen on 127.0.0.1:{port} \(.*address already in use\); is "
            r"another program using the port\?")


def test_record_with_the_webxr_port_taken_fails_at_once_in_one_line(tmp_path, port_taken):
    port, rig = port_taken
    started = time.monotonic()
    # a connect timeout longer than the child may run: waiting it out would time the test out
    ran = run_cli(["record", rig, "--duration", "3", "--no-preview", "--connect-timeout", "300",
                   "--out", tmp_path / "s.mcap"], timeout=240)
    took = time.monotonic() - started
    assert ran.returncode == 1, (ran.stdout, ran.stderr)
    assert not has_traceback(ran.stderr) and ran.stdout.strip() == "", ran.stdout
    assert re.fullmatch(cannot_listen(port), ran.stderr.strip()), ran.stderr
    assert took < 240


def test_record_with_the_terminal_preview_and_the_webxr_port_taken_fails_at_once_in_one_line(tmp_path, port_taken):
    """The preview in a real terminal (a pty), no --duration: nobody waits for the devices there, so the
    preview itself must end the session when a device cannot start, not show a table that never fills."""
    port, rig = port_taken
    master, slave = pty.openpty()
    proc = subprocess.Popen(TELEPREV + ["record", str(rig), "--out", str(tmp_path / "s.mcap")], stdin=slave,
                            stdout=slave, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env=_env({"TERM": "xterm-256color"}), cwd=ROOT)
    os.close(slave)
    drain = threading.Thread(target=_drain, args=(master,), daemon=True)  # a full pty blocks the preview
    drain.start()
    try:
        _, stderr = proc.communicate(timeout=120)  # without the fix it runs until a q that never comes
    finally:
        if proc.poll() is None:
            proc.kill()
        drain.join(5)
        os.close(master)
    assert proc.returncode == 1, stderr
    assert not has_traceback(stderr)
    assert re.fullmatch(cannot_listen(port), stderr.strip()), stderr


def _drain(fd: int) -> None:
    while True:
        try:
            if not os.read(fd, 1 << 16):
                return
        except OSError:  # the pty's last writer has gone
            return


def test_a_certificate_folder_that_cannot_be_made_is_said_once_and_not_retried(tmp_path):
    (tmp_path / "a_file").write_text("")
    cls = load_plugin("webxr.glove")
    clock = SessionClock()
    device = cls("glove", cls.Settings(port=0, cert_dir="a_file/certs"), DeviceContext(clock, tmp_path))
    try:
        device.connect()
        raise AssertionError("connected")
    except DeviceStartError as exc:
        assert "cannot keep the page's certificate in" in str(exc) and "set cert_dir" in str(exc)
    events = []
    runner = DeviceRunner(device, lambda sample, now: events.append(sample.payload), clock, reconnect_s=0.05).start()
    try:
        wait_until(lambda: not runner.is_alive(), 10.0, what="the runner to stop trying")
    finally:
        runner.stop()
    stats = runner.stats()
    assert stats.start_failure.startswith("WebXR server 127.0.0.1:0: cannot keep the page's certificate")
    errors = [e.data["message"] for e in events if isinstance(e, Event) and e.data["event"] == "error"]
    assert errors == [f"cannot start: {stats.start_failure}"]


def test_calibrate_with_the_webxr_port_taken_fails_before_the_first_pose(tmp_path, port_taken):
    """It said "no glove or suit data arrived while holding 'open'" after the operator held the pose."""
    port, rig = port_taken
    ran = run_cli(["calibrate", rig, "--hold", "600", "--out", tmp_path / "ada.toml"], timeout=240)
    assert ran.returncode == 2, (ran.stdout, ran.stderr)
    assert not has_traceback(ran.stderr)
    assert re.fullmatch(cannot_listen(port), ran.stderr.strip()), ran.stderr
    assert "open" not in ran.stdout  # no pose was asked for
    assert not (tmp_path / "ada.toml").exists()
