"""A script prelude for tests that count which numba kernels a fresh process has compiled or loaded:
`loaded()` (every kernel signature of teleprev.kernels in memory) and `run_steps(p)` (a few steps of a
pipeline, engaged from the third on, and eval's batched glove preparation)."""

import textwrap

PRELUDE = textwrap.dedent("""
    import importlib, pkgutil, sys

    import numpy as np
    from numba.core.registry import CPUDispatcher

    import teleprev.kernels
    from teleprev.human.smplx import HAND_POSE_NAMES
    from teleprev.assembly import build_pipeline
    from teleprev.messages import JointSample, PoseSample
    from teleprev.pipeline.step import PipelineState, StepInputs
    from teleprev.rig import load_rig

    modules = [importlib.import_module("teleprev.kernels." + m.name) for m in
    pkgutil.iter_modules(teleprev.kernels.__path__)]

    def loaded():
        return {(m.__name__, name, str(sig)) for m in modules for name, f in vars(m).items()
                if isinstance(f, CPUDispatcher) for sig in f.signatures}

    def run_steps(p):
        pose = np.zeros(45)
        pose[2::3] = 0.9  # a bent hand: the Corrector, its networks and the guard all run
        state = PipelineState()
        samples = []
        for k in range(6):
            t = 1_000_000 + k * 8_333_333
            hand = JointSample(t, HAND_POSE_NAMES, pose + 0.01 * k)
            samples.append(hand)
            inputs = StepInputs(t, hand, PoseSample(t, "suit", np.array([0.3, 0.0, 1.2 + 0.01 * k]),
                                                    np.array([1.0, 0.0, 0.0, 0.0])),
                                JointSample(t, p.arm_names, np.array([0.0, -0.35, -0.75, 0.0, 1.1, 0.0])),
                                JointSample(t, p.effector_names, np.zeros(len(p.effector_names))))
            if k == 2:
                state, why = p.set_mode(state, "execute", inputs)
                assert not why, why
            state = p.step(state, inputs).state
        p.prepare_hands(samples)  # eval's batch
        return state
""")
