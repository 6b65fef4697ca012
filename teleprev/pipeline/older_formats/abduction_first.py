"""Formats up to 4 read the glove abduction first, the twist about the bone taken off first (the current
format reads it flexion first, teleprev/human/smplx.py): the compiled reading of formats 3 and 4
(kernels/glove.py: prepare_rows_abduction_first). Format 4 differs from the current one in nothing else:
its commands come from the planner, as now."""

from __future__ import annotations

from teleprev.kernels import glove as glove_kernels
from teleprev.pipeline.step import Pipeline


class AbductionFirstPipeline(Pipeline):
    read_gloves = staticmethod(glove_kernels.prepare_rows_abduction_first)
