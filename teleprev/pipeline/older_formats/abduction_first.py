"""Formats up to 4 read the glove abduction first, the twist about the bone taken off first (the current
format reads it flexion first, teleprev/human/smplx.py): the compiled reading of formats 3 and 4
(kernels/glove.py: prepare_rows_abduction_first). Format 4's commands come from the planner, as format 5's
do (resuming at full speed after input loss, as format 5 did)."""

from __future__ import annotations

from teleprev.kernels import glove as glove_kernels
from teleprev.pipeline.older_formats.immediate_resume import ImmediateResumePipeline


class AbductionFirstPipeline(ImmediateResumePipeline):
    read_gloves = staticmethod(glove_kernels.prepare_rows_abduction_first)
