"""``SENSORIMOTOR_PORTABLE=1``: every numerical library on the code path of a 2013 x86 CPU.

The same seed gives the same bytes on one kind of CPU. Across kinds it does not: MKL, oneDNN,
PyTorch's own kernels and numba each pick their instructions (AVX-512 or AVX2, vector widths
that change the order of float sums) from the CPU they run on. Pinning all four to AVX2 with
FMA (Intel Haswell, 2013; every AMD EPYC) removes that choice. MKL documents the same results
on any CPU in its pinned mode (Conditional Numerical Reproducibility, same thread count); for
the others it follows from running the same instructions. The settings are environment
variables that each library reads once, when it loads: they are set here, on ``import
sensorimotor``, before any of them, and worker processes inherit them. The cost and what was
checked are in docs/DESIGN.md ("Determinism").
"""

from __future__ import annotations

import os
import sys
import warnings

SWITCH = "SENSORIMOTOR_PORTABLE"
SETTINGS = {
    "MKL_CBWR": "AVX2",  # MKL: the AVX2 code path, reproducible across CPUs
    "ONEDNN_MAX_CPU_ISA": "AVX2",  # oneDNN (some of torch's products)
    "ATEN_CPU_CAPABILITY": "avx2",  # PyTorch's own vectorised kernels
    "NUMBA_CPU_NAME": "haswell",  # numba's kernels (the simulator, the LSTM cells)
}
LIBRARIES = ("torch", "numba", "numpy")  # what must not be loaded before the settings


def apply() -> bool:
    """Set ``SETTINGS`` (those not already set) when ``SENSORIMOTOR_PORTABLE`` is 1; warn if a
    library read its own choice before. Returns whether the switch is on."""
    if os.environ.get(SWITCH, "") != "1":
        return False
    late = [name for name in LIBRARIES if name in sys.modules]
    for key, value in SETTINGS.items():
        os.environ.setdefault(key, value)
    if late:
        warnings.warn(
            f"{SWITCH}=1 came after {', '.join(late)} loaded: import sensorimotor first (or set "
            f"{', '.join(SETTINGS)} yourself) for it to take effect",
            stacklevel=2,
        )
    return True
