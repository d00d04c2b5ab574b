"""The synthetic systems benchmarked by name, and the budget and band width each is judged at.

One source of truth for ``rapt-plan search`` and ``benchmarks/``: a system is
built by :func:`get_system` and scored at its :data:`REFERENCE_SETTINGS`.
"""

from __future__ import annotations

from collections.abc import Callable

from rapt.errors import InputError
from rapt.testfunctions.base import SyntheticSystem
from rapt.testfunctions.composites import Composite8D, Screened
from rapt.testfunctions.shapes import Custom2D, Plates2D, Plates3D

__all__ = ["SYSTEMS", "get_system", "REFERENCE_SETTINGS", "search_output_types"]


def _plates3d_screened() -> Screened:
    return Screened(Plates3D(), 4, name="plates3d-screened")


SYSTEMS: dict[str, Callable[[], SyntheticSystem]] = {
    "custom2d": Custom2D,
    "plates2d": Plates2D,
    "plates3d": Plates3D,
    "plates3d-screened": _plates3d_screened,
    "composite8d": Composite8D,
}


def get_system(name: str) -> SyntheticSystem:
    """Build the registered system called ``name`` (see :data:`SYSTEMS`)."""
    try:
        factory = SYSTEMS[name]
    except (KeyError, TypeError):
        raise InputError(f"unknown system {name!r}; choose one of: {', '.join(sorted(SYSTEMS))}") from None
    return factory()


#: Budget and boundary width D_eps at which each registered system is benchmarked.  As in
#: the dissertation, D_eps is narrow enough that a Sobol design's coverage at that budget
#: stays well below 40% (a wide band is covered by any design and says nothing).
REFERENCE_SETTINGS: dict[str, tuple[int, float]] = {
    "custom2d": (1000, 0.01),
    "plates2d": (1000, 0.01),
    "plates3d": (3000, 0.02),
    "plates3d-screened": (10000, 0.02),
    "composite8d": (10000, 0.003),
}


def search_output_types(system: SyntheticSystem) -> tuple[str, ...]:
    """The ``output_types`` to pass to :func:`rapt.search` for ``system``."""
    return tuple("continuous" if t == "continuous" else "categorical" for t in system.output_types)
