"""The arithmetic of older session formats, kept so that their sessions re-run bit for bit."""

from teleprev.pipeline.older_formats.numpy_arithmetic import (NumpyArmIK, NumpyArmRetargeter, NumpyCorrector,
                                                             NumpyPipeline, NumpySweptCheck, StepCommandsPipeline)

__all__ = ["NumpyArmIK", "NumpyArmRetargeter", "NumpyCorrector", "NumpyPipeline", "NumpySweptCheck",
           "StepCommandsPipeline"]
