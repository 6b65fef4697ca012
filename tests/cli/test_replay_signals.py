"""`teleprev replay ... --out` stopped by SIGTERM or SIGHUP stops as `record` does (teleprev.cli.signals): the
robot's devices stop, the replay's recording is finalized, one line says which signal, exit 128 + the signal."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

from teleprev.session.reader import SessionReader
from teleprev.session.recorder import RECORDER_RECORD
from tests.helpers.faults import has_traceback, start_cli, wait_for_file

FIXTURE = Path(__file__).parents[1] / "fixtures" / "sim_v2.mcap"


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP], ids=["sigterm", "sighup"])
def test_a_signal_finalizes_the_replays_recording(tmp_path, sig):
    out = tmp_path / "replay.mcap"
    proc = start_cli(["replay", FIXTURE, "--to", "sim", "--engage-after", "0", "--no-preview", "--out", out])
    try:
        wait_for_file(out, 20_000, timeout=60)  # the replay is recording
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig, (proc.returncode, stdout, stderr)
    assert not has_traceback(stdout + stderr)
    assert f"stopped by {sig.name}" in stdout and f"replay recorded in {out}" in " ".join(stdout.split())
    with SessionReader(out, verify_crc=True) as reader:  # complete: footer, summary, the recorder's counters
        assert RECORDER_RECORD in reader.metadata
        assert reader.topics["/command/arm"].message_count > 10
