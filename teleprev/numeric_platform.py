"""One numeric platform for every teleprev process, so a session reproduces bit for bit on another machine.

numpy picks its float64 sin/cos/exp kernels by CPU (AVX-512 machines get Intel SVML, others not) and
OpenBLAS picks its matrix kernels the same way; the results differ in the last bits, and a CCN output
that differs by 1e-16 is enough to change a corrected hand command. Pinning both to the AVX2 level
(every x86-64 CPU from 2013 on) makes the pipeline's arithmetic the same on every such machine, so
`teleprev eval` reproduces sessions recorded elsewhere. It must run before numpy is imported, which is
why `teleprev/__init__.py` calls it first; a process that imported numpy earlier keeps numpy's choice
(`pinned()` then says False, and eval reports it).
"""

from __future__ import annotations

import os
import sys

# numpy's names for the CPU features above AVX2 (it ignores the ones it does not know).
_ABOVE_AVX2 = "AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR AVX512FP16"
PLATFORM = "x86-64-v3 (numpy AVX2, OpenBLAS Haswell)"


def _cpu_has_avx2() -> bool:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return " avx2 " in f" {line.split(':', 1)[1].strip()} "
    except OSError:
        pass
    return False


def pin() -> None:
    """Set the environment numpy and OpenBLAS read at import; a no-op off x86-64 Linux or after numpy loaded."""
    if "numpy" in sys.modules or not _cpu_has_avx2():
        return
    os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", _ABOVE_AVX2)
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")


def pinned() -> bool:
    """Whether this process computes on PLATFORM (recorded in session metadata next to the model hashes)."""
    return os.environ.get("OPENBLAS_CORETYPE") == "Haswell" and "AVX512_SKX" in os.environ.get(
        "NPY_DISABLE_CPU_FEATURES", ""
    )


def describe() -> str:
    return PLATFORM if pinned() else f"native ({sys.platform})"
