"""teleprev.kernels.warm() (what scripts/setup.sh runs) compiles every kernel for the types the pipeline
passes: after it, building and stepping every sim rig's pipeline, and the eval's batched preparation,
compile or load nothing more (a kernel called with other types would compile in a live loop)."""

import subprocess
import sys
import textwrap
from pathlib import Path

from tests.helpers.kernel_loads import PRELUDE

RIGS = Path(__file__).parents[2] / "rigs"

SCRIPT = PRELUDE + textwrap.dedent("""
    teleprev.kernels.warm()
    warmed = loaded()
    for rig in sys.argv[1:]:
        run_steps(build_pipeline(load_rig(rig)))
    print(sorted(loaded() - warmed))
""")



def test_warm_leaves_nothing_for_the_pipeline_to_compile():
    rigs = [str(RIGS / r) for r in ("sim.toml", "sim_gripper.toml", "sim_vacuum.toml")]
    out = subprocess.run([sys.executable, "-c", SCRIPT, *rigs], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", "compiled or loaded after warm(): " + out.stdout
