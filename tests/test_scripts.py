"""scripts/setup.sh keeps what an earlier setup installed: demo.sh's plain setup after test.sh's leaves the
`ray` extra that the tests need (uv sync removes what the call did not ask for, unless told otherwise)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def setup_would(*args: str) -> str:
    run = subprocess.run(["bash", "scripts/setup.sh", *args], cwd=ROOT, capture_output=True, text=True, timeout=120,
                         env={**os.environ, "TELEPREV_SETUP_DRY_RUN": "1"})
    assert run.returncode == 0, run.stderr
    return run.stdout + run.stderr


def test_the_demos_setup_leaves_the_extra_the_tests_installed():
    import ray  # noqa: F401  installed by test.sh (bash scripts/setup.sh --extra ray)

    said = setup_would()  # what demo.sh runs
    assert "Would uninstall" not in said and "ray" not in said, said
    assert "Would make no changes" in setup_would("--extra", "ray"), "test.sh's setup is not in place"
