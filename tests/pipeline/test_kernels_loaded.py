"""A compiled pipeline loads every kernel when it is built, so that no live step pays numba's load (about
20 ms the first time a kernel is called)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

RIGS = Path(__file__).parents[2] / "rigs"

SCRIPT = textwrap.dedent("""
    import sys

    import numpy as np
    from numba.core.registry import CPUDispatcher
    import importlib, pkgutil
    import teleprev.kernels
    from teleprev.live.build import build_pipeline
    from teleprev.messages import JointSample, PoseSample
    from teleprev.pipeline.step import PipelineState, StepInputs
    from teleprev.rig import load_rig
    from teleprev.human.smplx import HAND_POSE_NAMES

    modules = [importlib.import_module("teleprev.kernels." + m.name) for m in pkgutil.iter_modules(teleprev.kernels.__path__)]

    def loaded():
        return {(m.__name__, name, str(sig)) for m in modules for name, f in vars(m).items()
                if isinstance(f, CPUDispatcher) for sig in f.signatures}

    p = build_pipeline(load_rig(sys.argv[1]))
    before = loaded()
    pose = np.zeros(45)
    pose[2::3] = 0.9  # a bent hand: the Corrector, its networks and the guard all run
    state = PipelineState()
    for k in range(6):
        t = 1_000_000 + k * 8_333_333
        inputs = StepInputs(t, JointSample(t, HAND_POSE_NAMES, pose + 0.01 * k),
                            PoseSample(t, "suit", np.array([0.3, 0.0, 1.2 + 0.01 * k]), np.array([1.0, 0.0, 0.0, 0.0])),
                            JointSample(t, p.arm_names, np.array([0.0, -0.35, -0.75, 0.0, 1.1, 0.0])),
                            JointSample(t, p.effector_names, np.zeros(len(p.effector_names))))
        if k == 2:
            state, why = p.set_mode(state, "execute", inputs)
            assert not why, why
        state = p.step(state, inputs).state
    assert state.motion is not None  # the motion limits (and, for a hand, the swept check) ran
    print(sorted(loaded() - before))
""")


@pytest.mark.parametrize("rig", ["sim.toml", "sim_gripper.toml", "sim_vacuum.toml"])
def test_a_compiled_pipeline_loads_its_kernels_when_built(rig):
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(RIGS / rig)], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[]", "kernels loaded by the first steps: " + out.stdout
