"""Every bench runs: `python bench/NAME.py --quick --json` for each bench/*.py on disk (a new bench is in
at once), as a user runs it, and prints every figure its docstring's "JSON keys:" section declares, finite
and of the declared type (the convention: bench/common.py's docstring). A bench that crashes, prints
NaN or null for a declared figure, or declares nothing fails here."""

from __future__ import annotations

import ast
import importlib.util
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "bench"
BENCHES = sorted(p for p in BENCH.glob("*.py") if p.name != "common.py")

# Seconds a quick run may take here (2 shared cores); a bench not named gets DEFAULT_LIMIT_S. Well above
# what they take (bench/README: the figures of the quick runs), so that only a hang or a bench that
# stopped being quick trips it.
DEFAULT_LIMIT_S = 90
LIMIT_S = {}


def _common():
    spec = importlib.util.spec_from_file_location("bench_common", BENCH / "common.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def declared(bench: Path) -> dict[str, str]:
    doc = ast.get_docstring(ast.parse(bench.read_text()))
    assert doc, f"{bench.name} has no module docstring"
    try:
        return _common().declared_keys(doc)
    except ValueError as e:
        raise AssertionError(f"{bench.name}: {e}") from None


def problems(figures: dict, keys: dict[str, str]) -> list[str]:
    """What is wrong with a quick run's figures against the declared keys (empty: nothing)."""
    types = _common().KEY_TYPES
    out = [f"{k}: missing" for k in keys if k not in figures]
    for k, kind in keys.items():
        v = figures.get(k)
        if k in figures and (v is None or (isinstance(v, bool) and kind != "bool") or not isinstance(v, types[kind])):
            out.append(f"{k}: {v!r} is not a {kind}")

    def walk(where: str, v) -> None:
        if isinstance(v, float) and not math.isfinite(v):
            out.append(f"{where}: {v}")
        elif isinstance(v, dict):
            for key, item in v.items():
                walk(f"{where}.{key}", item)
        elif isinstance(v, list):
            for n, item in enumerate(v):
                walk(f"{where}[{n}]", item)

    for k, v in figures.items():
        walk(k, v)
    return out


def test_the_checks_catch_what_they_should():
    keys = {"a": "float", "n": "int", "ok": "bool"}
    assert problems({"a": 1, "n": 2, "ok": False, "extra": [1.5, {"x": "y"}]}, keys) == []
    assert problems({"a": None, "n": True, "ok": 1, "x": {"y": [float("inf")]}}, keys) == [
        "a: None is not a float", "n: True is not a int", "ok: 1 is not a bool", "x.y[0]: inf"]
    assert problems({}, {"a": "float"}) == ["a: missing"]


def test_a_bad_declaration_is_refused():
    declared_keys = _common().declared_keys
    assert declared_keys("Title.\n\nJSON keys:\n    a  float\n    b int\n\nmore prose") == {"a": "float", "b": "int"}
    for bad in ("no section", "JSON keys:\n", "JSON keys:\n    a  number", "JSON keys:\n    a float why"):
        with pytest.raises(ValueError):
            declared_keys(bad)


def _params():
    for bench in BENCHES:
        limit = LIMIT_S.get(bench.stem, DEFAULT_LIMIT_S)
        yield pytest.param(bench, limit, id=bench.stem, marks=pytest.mark.timeout(limit + 30))


@pytest.mark.parametrize(("bench", "limit_s"), _params())
def test_quick_mode_prints_every_declared_figure(bench: Path, limit_s: int):
    keys = declared(bench)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "devices"),
                                                         os.environ.get("PYTHONPATH", "")])}
    t = time.perf_counter()
    try:
        run = subprocess.run([sys.executable, str(bench), "--quick", "--json"], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=limit_s)
    except subprocess.TimeoutExpired as e:
        raise AssertionError(f"{bench.name} --quick ran past {limit_s} s; its stderr's end:\n"
                             f"{(e.stderr or b'')[-3000:]!r}") from None
    print(f"{bench.name} --quick: {time.perf_counter() - t:.1f} s")
    assert run.returncode == 0, f"{bench.name} --quick exited {run.returncode}:\n{run.stderr[-3000:]}"
    lines = run.stdout.strip().splitlines()
    assert lines, f"{bench.name} --quick printed nothing on stdout:\n{run.stderr[-3000:]}"

    def refuse(constant):
        raise ValueError(f"not strict JSON: {constant}")

    figures = json.loads(lines[-1], parse_constant=refuse)
    assert isinstance(figures, dict), f"{bench.name}: the last line is not a JSON object: {lines[-1][:200]}"
    wrong = problems(figures, keys)
    assert not wrong, f"{bench.name} --quick --json:\n  " + "\n  ".join(wrong)
