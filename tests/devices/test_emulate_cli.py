"""`teleprev devices emulate xarm|leap` prints rig keys that `teleprev devices check` then reads through the
real SDKs; an address it cannot have is one line and exit status 2."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from teleprev.emulators.listening import free_loopback_host, listen

CLI = [sys.executable, "-m", "teleprev.cli.app"]


def start_emulator(*args) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen([*CLI, "devices", "emulate", *args, "--seconds", "60"], stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, env={**os.environ, "COLUMNS": "200"})
    lines, deadline = [], time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line)
        if line.startswith("Ctrl-C") or line.startswith("stops in"):
            break
    text = "".join(lines)
    assert "[devices." in text, text
    return proc, text[text.index("[devices."):text.rindex("\n\n")] + "\n"


def test_emulate_prints_rig_keys_that_devices_check_reads(tmp_path):
    host = free_loopback_host((502, 30001, 30002))
    arm, arm_keys = start_emulator("xarm", "--host", host)
    hand, hand_keys = start_emulator("leap", "--port", str(tmp_path / "ttyLEAP"))
    try:
        assert f'host = "{host}"' in arm_keys and f'port = "{tmp_path / "ttyLEAP"}"' in hand_keys
        rig = tmp_path / "rig.toml"
        rig.write_text(arm_keys + "\n" + hand_keys)
        check = subprocess.run([*CLI, "devices", "check", str(rig), "--seconds", "1.5"], capture_output=True,
                               text=True, timeout=120, env={**os.environ, "COLUMNS": "200"})
        out = check.stdout + check.stderr
        assert check.returncode == 0, out
        assert "all 2 devices streaming" in out
        # leap.hand set the emulated adapter's latency timer to 1 ms, and check says so
        assert "hand: USB adapter latency timer 1 ms (" in out, out
        rows = {ln.split()[0]: ln.split() for ln in out.splitlines() if ln.split()[:1] in (["arm"], ["hand"])}
        assert rows["arm"][1:4] == ["xarm.arm", "arm", "ok"] and rows["hand"][1:4] == ["leap.hand", "hand", "ok"]
    finally:
        for proc in (arm, hand):
            proc.send_signal(signal.SIGTERM)
            proc.wait(10)
    assert arm.returncode == 0 and hand.returncode == 0
    assert not (tmp_path / "ttyLEAP").exists()  # the bus is unplugged when the emulator stops


def test_an_address_that_is_taken_is_one_line():
    host = free_loopback_host((502, 30001, 30002))
    taken = listen(host, 502)
    try:
        proc = subprocess.run([*CLI, "devices", "emulate", "xarm", "--host", host, "--seconds", "1"],
                              capture_output=True, text=True, timeout=60, env={**os.environ, "COLUMNS": "200"})
    finally:
        taken.close()
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: cannot listen on {host}:502: it is taken (another emulator, or a " \
                                  "controller on this machine); pick another loopback address, e.g. --host 127.0.0.2"


def test_emulate_leap_refuses_a_path_that_exists(tmp_path):
    taken = tmp_path / "notes.txt"
    taken.write_text("keep me")
    proc = subprocess.run([*CLI, "devices", "emulate", "leap", "--port", str(taken), "--seconds", "1"],
                          capture_output=True, text=True, timeout=60, env={**os.environ, "COLUMNS": "300"})
    assert proc.returncode == 2
    assert proc.stderr.strip() == (f"error: cannot put the emulated bus at {taken}: it already exists; pick a path "
                                   "that does not exist (or leave out --port)")
    assert taken.read_text() == "keep me" and not taken.is_symlink()


@pytest.mark.parametrize("args, said", [
    (["xarm", "--dof", "5"], "error: --dof must be 6 or 7, got 5"),  # exit 2 without a word on stderr
    (["xarm", "--seconds", "inf"], "error: --seconds must be 0 or more seconds, got inf"),  # ran for ever
    (["arm"], "error: nothing to emulate called 'arm': xarm or leap"),
])
def test_a_value_it_cannot_emulate_is_one_line_on_stderr(args, said):
    proc = subprocess.run([*CLI, "devices", "emulate", *args], capture_output=True, text=True, timeout=60,
                          env={**os.environ, "COLUMNS": "200"})
    assert (proc.returncode, proc.stderr.strip(), proc.stdout) == (2, said, "")
