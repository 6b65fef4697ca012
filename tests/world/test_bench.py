"""bench/physics.py --quick runs and prints the issue's keys in one JSON object last."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_physics_bench_prints_its_figures_as_json_last():
    done = subprocess.run([sys.executable, str(ROOT / "bench" / "physics.py"), "--quick", "--json"],
                          check=False, capture_output=True, text=True, timeout=500, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    figures = json.loads(done.stdout.strip().splitlines()[-1])
    assert figures["physics_realtime_x"] > 0 and figures["render_fps"] > 0
    tasks = ("pick_place", "hang", "pour", "box_rotation", "cup_stack")
    assert figures["physics_realtime_x"] == min(figures[f"physics_realtime_x[{t}]"] for t in tasks)
    assert "render_fps" in done.stderr  # the table, beside the JSON
