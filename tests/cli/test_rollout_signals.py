"""`teleprev rollout` stopped by SIGINT, SIGTERM or SIGHUP stops as `record` and `replay --out` do
(teleprev.cli.signals): the robot brakes, the rollout's session is finalized, one line says which signal and
that the file is complete, exit 128 + the signal."""

from __future__ import annotations

import signal

import pytest

from teleprev.session.reader import SessionReader
from teleprev.session.recorder import RECORDER_RECORD
from tests.helpers.faults import has_traceback, start_cli, wait_for_file
from tests.helpers.policies import train_tiny_act


@pytest.fixture(scope="module")
def policy(sim_dataset, tmp_path_factory):
    return train_tiny_act(sim_dataset, "lab/sim", tmp_path_factory.mktemp("train") / "act")


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP], ids=["sigint", "sigterm", "sighup"])
def test_a_signal_finalizes_the_rollouts_session(tmp_path, policy, sig):
    out = tmp_path / "rollout.mcap"
    proc = start_cli(["rollout", "--policy", policy, "--episodes", "1", "--episode-time", "120", "--engage-after",
                      "0.5", "--out", out], env={"HF_HUB_OFFLINE": "1"})
    try:
        wait_for_file(out, 100_000, timeout=180)  # the policy loaded, the rollout is recording
        proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + sig, (proc.returncode, stdout, stderr)
    assert not has_traceback(stdout + stderr), stderr
    assert f"stopped by {sig.name}; {out} is complete" in " ".join(stdout.split()), stdout
    with SessionReader(out, verify_crc=True) as reader:  # complete: footer, summary, the recorder's counters
        assert RECORDER_RECORD in reader.metadata
        assert reader.metadata["policy"]["type"] == "act"
