"""The machine a run was computed on, recorded beside the library versions of every run.

Two CPUs can round the same computation differently in the last bits: OpenBLAS picks a kernel per
processor at start-up (``Haswell``, ``SkylakeX``, ``Zen``, ...), and each kernel orders its sums
in its own way. The kernel and the processor are stored with every run, so that a resume that
diverges can name them (:func:`corl.store.replay`).
"""

from __future__ import annotations

import ctypes
import platform
from functools import lru_cache
from pathlib import Path

__all__ = ["machine_info", "blas_kernel"]

# Entry points that name OpenBLAS's kernel, under the symbol names of its different builds.
_CORENAME_SYMBOLS = ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename",
                     "openblas_get_corename64_", "openblas_get_corename")


@lru_cache(maxsize=1)
def blas_kernel() -> str | None:
    """The kernel OpenBLAS runs on this CPU (e.g. "Haswell"), from the library numpy bundles, or None."""
    try:
        import numpy as np

        libs = sorted((Path(np.__file__).parent.parent / "numpy.libs").glob("*openblas*"))
    except Exception:
        return None
    for lib in libs:
        try:
            handle = ctypes.CDLL(str(lib))
        except OSError:
            continue
        for symbol in _CORENAME_SYMBOLS:
            fn = getattr(handle, symbol, None)
            if fn is not None:
                fn.restype = ctypes.c_char_p
                name = fn()
                return name.decode(errors="replace").strip() if name else None
    return None


@lru_cache(maxsize=1)
def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info() -> dict[str, str]:
    """``cpu`` (the processor's model name) and ``blas_kernel`` (when OpenBLAS reports one)."""
    info = {"cpu": _cpu_model()}
    kernel = blas_kernel()
    if kernel:
        info["blas_kernel"] = kernel
    return info
