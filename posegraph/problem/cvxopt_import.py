"""cvxopt's CHOLMOD, imported with OpenBLAS kernels that suit the CPU.

cvxopt's wheel bundles its own OpenBLAS (0.3.15), which picks its kernels from the CPU's model
when it loads. A CPU it does not know (a virtual Xeon that reports no model) gets its Prescott
kernels (SSE3): CHOLMOD's supernodal factorisation of sphere2500 then takes about 1.7× as long
as with its Haswell (AVX2) kernels (docs/benchmarks.md). Unless the user chose
(``OPENBLAS_CORETYPE``), the kernels are named here from the instruction sets numpy detects,
for this import only: the variable is removed again, so child processes choose for themselves.
"""

from __future__ import annotations

import functools
import os

CORE_TYPES = (("AVX512_SKX", "SkylakeX"), ("AVX2", "Haswell"))
"""numpy's name of an instruction set, and OpenBLAS's kernels that need it, best first
(Haswell's also need FMA3)."""


def _cpu_features() -> dict[str, bool]:
    """The instruction sets numpy detected on this CPU (empty if this numpy does not say)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # numpy < 2
        try:
            from numpy.core._multiarray_umath import __cpu_features__
        except ImportError:
            return {}
    return __cpu_features__


def core_type(features: dict[str, bool]) -> str | None:
    """The OpenBLAS kernels for a CPU with these instruction sets (None: leave OpenBLAS to
    choose)."""
    if not features.get("FMA3"):
        return None
    return next((core for name, core in CORE_TYPES if features.get(name)), None)


@functools.cache
def import_cholmod():
    """``cvxopt.cholmod``, the environment set once; ``ImportError`` if cvxopt is not
    installed."""
    chosen = None if "OPENBLAS_CORETYPE" in os.environ else core_type(_cpu_features())
    if chosen is not None:
        os.environ["OPENBLAS_CORETYPE"] = chosen
    try:
        import cvxopt.cholmod
    finally:
        if chosen is not None:
            del os.environ["OPENBLAS_CORETYPE"]
    return cvxopt.cholmod
