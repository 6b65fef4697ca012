"""The code passes `ruff check` with the configuration in pyproject.toml (pyflakes, isort, pycodestyle at
120 columns, pyupgrade): the suite fails listing every violation, one a line."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def ruff(*args: str, stdin: str | None = None) -> subprocess.CompletedProcess:
    assert importlib.util.find_spec("ruff"), "ruff is not installed: it is in the dev group (uv sync)"
    return subprocess.run([sys.executable, "-m", "ruff", *args], cwd=ROOT, input=stdin, capture_output=True,
                          text=True)


def test_the_code_passes_ruff():
    run = ruff("check", "--no-cache", "--output-format", "concise", ".")
    if run.returncode:
        pytest.fail(f"ruff check (`ruff check --fix` mends those marked [*]):\n{run.stdout}{run.stderr}", pytrace=False)


def test_ruff_checks_our_code_and_what_it_is_asked_to():
    """Neither an exclude too wide nor a rule left out passes the check above by checking nothing."""
    listed = ruff("check", "--no-cache", "--show-files", ".")
    files = {Path(line.strip()).resolve().relative_to(ROOT).as_posix() for line in listed.stdout.splitlines()
             if line.strip().endswith(".py")}
    for ours in ("teleprev/session/codec.py", "devices/teleprev_devices/vmc/plugins.py", "tests/test_ruff.py",
                 "bench/common.py"):
        assert ours in files, ours
    assert not [f for f in files if "node_modules" in f or f.startswith(".venv/")]

    sample = f"from typing import Optional\nimport os\n\n\ndef f(x: Optional[int]) -> int:\n    return {'1 + ' * 40}1\n"
    run = ruff("check", "--no-cache", "--output-format", "concise", "--stdin-filename", "tests/sample.py", "-",
               stdin=sample)
    found = set(re.findall(r":\d+:\d+: ([A-Z]+\d+)", run.stdout))
    assert found == {"F401", "I001", "E501", "UP045"}, run.stdout
