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
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "bench"
BENCHES = sorted(p for p in BENCH.glob("*.py") if p.name != "common.py")

# Seconds a quick run may take (2 shared cores); a bench not named gets DEFAULT_LIMIT_S. About three
# times what each takes here, so that only a hang, or a bench that stopped being quick, trips it.
DEFAULT_LIMIT_S = 120
LIMIT_S = {"bimanual": 200, "corpus": 200, "export": 200, "faults": 200, "physics": 400, "realtime": 240,
           "rollout": 200}


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


# Quick runs at once: a test starts the next bench's run before it waits for its own, so that one
# bench's sleeps and start-up (recordings run in real time, commands start interpreters) overlap
# another's work. Two, for the 2-core machine the suite is timed on.
PARALLEL = 2


@dataclass
class QuickRun:
    bench: Path
    limit_s: float
    folder: Path
    proc: subprocess.Popen | None = None
    started: float = 0.0

    def start(self) -> None:
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "devices"),
                                                             os.environ.get("PYTHONPATH", "")])}
        self.started = time.perf_counter()
        with open(self.folder / "stdout", "w") as out, open(self.folder / "stderr", "w") as err:
            self.proc = subprocess.Popen([sys.executable, str(self.bench), "--quick", "--json"], cwd=ROOT, env=env,
                                         stdout=out, stderr=err, text=True, start_new_session=True)

    def wait(self) -> tuple[int | None, str, str, float]:
        """(exit code, None when it ran past its limit and was killed; stdout; stderr; seconds)."""
        try:
            code = self.proc.wait(timeout=max(0.0, self.started + self.limit_s - time.perf_counter()))
        except subprocess.TimeoutExpired:
            os.killpg(self.proc.pid, signal.SIGKILL)  # the bench and the commands it started
            self.proc.wait()
            code = None
        took = time.perf_counter() - self.started
        return code, (self.folder / "stdout").read_text(), (self.folder / "stderr").read_text(), took


@pytest.fixture(scope="module")
def quick_runs(request, tmp_path_factory):
    """The quick runs of the benches this session runs, in the order their tests come, started
    PARALLEL at a time; `take(bench)` waits for one."""
    wanted = [item.callspec.params["bench"] for item in request.session.items
              if item.originalname == "test_quick_mode_prints_every_declared_figure"]
    runs = {b: QuickRun(b, LIMIT_S.get(b.stem, DEFAULT_LIMIT_S), tmp_path_factory.mktemp(b.stem)) for b in wanted}

    def running() -> int:
        return sum(r.proc is not None and r.proc.poll() is None for r in runs.values())

    def take(bench: Path) -> QuickRun:
        if runs[bench].proc is None:
            runs[bench].start()
        for b in wanted[wanted.index(bench) + 1:]:  # the next ones, while fewer than PARALLEL run
            if running() >= PARALLEL:
                break
            if runs[b].proc is None:
                runs[b].start()
        return runs[bench]

    yield take
    for run in runs.values():
        if run.proc is not None and run.proc.poll() is None:
            os.killpg(run.proc.pid, signal.SIGKILL)
            run.proc.wait()


def _params() -> list:
    return [pytest.param(b, id=b.stem, marks=pytest.mark.timeout(LIMIT_S.get(b.stem, DEFAULT_LIMIT_S) + 30))
            for b in BENCHES]


@pytest.mark.parametrize("bench", _params())
def test_quick_mode_prints_every_declared_figure(bench: Path, quick_runs):
    keys = declared(bench)
    run = quick_runs(bench)
    code, stdout, stderr, took = run.wait()
    print(f"{bench.name} --quick: {took:.1f} s")
    assert code is not None, f"{bench.name} --quick ran past {run.limit_s} s; its stderr's end:\n{stderr[-3000:]}"
    assert code == 0, f"{bench.name} --quick exited {code}:\n{stderr[-3000:]}"
    lines = stdout.strip().splitlines()
    assert lines, f"{bench.name} --quick printed nothing on stdout:\n{stderr[-3000:]}"

    def refuse(constant):
        raise ValueError(f"not strict JSON: {constant}")

    figures = json.loads(lines[-1], parse_constant=refuse)
    assert isinstance(figures, dict), f"{bench.name}: the last line is not a JSON object: {lines[-1][:200]}"
    wrong = problems(figures, keys)
    assert not wrong, (
        f"{bench.name} --quick --json:\n  " + "\n  ".join(wrong) + f"\nits stderr's end:\n{stderr[-3000:]}"
    )
