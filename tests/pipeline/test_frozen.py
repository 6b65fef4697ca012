"""evolve: the pipeline's fast dataclasses.replace."""

import dataclasses

import numpy as np
import pytest

from teleprev.pipeline.frozen import evolve
from teleprev.pipeline.planner import EstimateState
from teleprev.pipeline.step import PipelineState


def test_evolve_equals_replace_and_leaves_the_original():
    s = PipelineState(step=4, arm_q=np.zeros(6))
    new = evolve(s, step=5, mode="execute")
    assert new == dataclasses.replace(s, step=5, mode="execute")
    assert (s.step, s.mode) == (4, "preview") and new.arm_q is s.arm_q
    with pytest.raises(dataclasses.FrozenInstanceError):
        new.step = 6


def test_evolve_refuses_a_name_that_is_not_a_field():
    with pytest.raises(TypeError, match="arm_nss"):
        evolve(EstimateState(), arm_nss=1)
