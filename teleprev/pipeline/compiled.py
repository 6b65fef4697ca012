"""Every numba kernel the pipeline runs, loaded (or compiled, the first time) in one call.

scripts/setup.sh calls warm() so that numba's on-disk cache holds every kernel before the first record or
eval; eval's worker fork server calls it so that workers start with them loaded. Nothing here is
imported by `teleprev --help`.
"""

from __future__ import annotations


def warm() -> None:
    from teleprev.noncollision.compiled import warm as noncollision
    from teleprev.kernels.glove import warm as hand
    from teleprev.kernels.motion import warm as motion
    from teleprev.pipeline.swept import warm as swept
    from teleprev.retarget.arm import warm as arm
    from teleprev.robot.collision import warm as checker
    from teleprev.robot.compiled_collision import warm as collision

    # (the IK's kernel: arm's ArmRetargeter(ArmIK(compiled=True)) loads it)
    for each in (collision, checker, arm, noncollision, hand, motion, swept):
        each()
