"""The numerical runtime that computed a plan: Python, the numerical libraries, the BLAS and the CPU paths.

A plan is the end of a long chain of floating-point work. The simulations near a boundary,
the classifiers, the refinement's bisections and the dithers' P values all sit there, and
NumPy promises identical numbers only for the same build on the same machine. ``plan.json``
therefore names what made it. A range that regenerates a plan elsewhere can then tell a
library or CPU difference from a changed mission.
"""

from __future__ import annotations

import importlib
import platform
from importlib import metadata

__all__ = ["numerical_runtime", "LIBRARIES"]

#: The distributions whose arithmetic a plan's numbers go through.
LIBRARIES = ("numpy", "scipy", "scikit-learn", "faiss-cpu")


def numerical_runtime() -> dict:
    """Python and :data:`LIBRARIES` versions, each BLAS in use (threadpoolctl's report: its implementation,
    version, CPU kernel and threading) and the CPU features NumPy's dispatch uses on this machine."""
    import numpy  # noqa: F401  (its BLAS is loaded with it: threadpoolctl reports loaded libraries)
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info  # type: ignore[import-untyped]

    versions: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    blas = sorted(  # in a fixed order: threadpoolctl lists them in the order they were loaded
        (
            {k: info.get(k) for k in ("internal_api", "version", "architecture", "threading_layer")}
            for info in threadpool_info()
            if info.get("user_api") == "blas"
        ),
        key=lambda b: tuple(str(b[k]) for k in ("internal_api", "version", "architecture", "threading_layer")),
    )
    try:  # NumPy 2.x, else 1.x
        core = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:
        core = importlib.import_module("numpy.core._multiarray_umath")
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        **versions,
        "blas": blas,
        "numpy_baseline": list(core.__cpu_baseline__),
        "numpy_dispatch": [name for name in core.__cpu_dispatch__ if core.__cpu_features__.get(name)],
    }
