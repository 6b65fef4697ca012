"""A compiled pipeline loads every kernel when it is built, so that no live step pays numba's load (about
20 ms the first time a kernel is called)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.helpers.kernel_loads import PRELUDE

RIGS = Path(__file__).parents[2] / "rigs"

SCRIPT = PRELUDE + textwrap.dedent("""
    p = build_pipeline(load_rig(sys.argv[1]))
    before = loaded()
    state = run_steps(p)
    assert state.estimates is not None  # the targets' velocity estimates ran
    print(sorted(loaded() - before))
""")



@pytest.mark.parametrize("rig", ["sim.toml", "sim_gripper.toml", "sim_vacuum.toml"])
def test_a_compiled_pipeline_loads_its_kernels_when_built(rig):
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(RIGS / rig)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", "kernels loaded by the first steps: " + out.stdout
