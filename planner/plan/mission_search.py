"""A mission's scenarios searched for performance boundaries: modes and boundary types per search.

``rapt-plan study`` runs a search method (and a baseline) over a mission's scenario space
and sets the searches side by side (Figure 3.12).  What a search steers on, how its runs
fall into the four performance modes and which boundaries between modes it found are
decided here, so the command only runs the searches and prints the table.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

import rapt
from rapt.boundaries import BoundaryPairs
from rapt.search import Study

__all__ = ["ROOT_OUTPUT_TYPES", "root_scores", "ModeSearch"]

# the two root scores (mission success, safety success) are pass/fail
ROOT_OUTPUT_TYPES: tuple[str, ...] = ("binary", "binary")


def root_scores(mission, *, seed: int = 0, stochastic: bool = False) -> Callable[[np.ndarray], np.ndarray]:
    """What a mission search steers on: the mission and safety success of each scenario (section 4.3.6)."""
    import sim.uuv

    def scores(X: np.ndarray) -> np.ndarray:
        return sim.uuv.simulate(mission, X, seed=seed, stochastic=stochastic).scores[:, :2]

    return scores


@dataclass(frozen=True)
class ModeSearch:
    """One search of a mission: its runs, their performance modes and the boundary pairs between modes.

    A run's mode is ``2 * mission success + safety success`` (an index into
    :data:`sim.uuv.scoring.MODE_NAMES`); the pairs' own labels index :attr:`present`.
    """

    method: str
    found: Study
    modes: np.ndarray  # (runs,) mode of each valid run
    pairs: BoundaryPairs | None  # None when the search met one mode only
    seconds: float

    @classmethod
    def of(cls, method: str, found: Study, seconds: float) -> ModeSearch:
        modes = (2 * found.Y[:, 0] + found.Y[:, 1]).astype(int)
        pairs = rapt.boundary_pairs(found.X, labels=modes) if np.unique(modes).size > 1 else None
        return cls(method, found, modes, pairs, seconds)

    @cached_property
    def present(self) -> list[int]:
        """The modes this search met, in order."""
        return sorted(set(self.modes.tolist()))

    @property
    def n_pairs(self) -> int:
        return len(self.pairs) if self.pairs is not None else 0

    def mode_share(self, mode: int) -> float:
        """Share of the valid runs in ``mode``."""
        return np.mean(self.modes == mode)

    def boundary_types(self) -> set[tuple[int, int]]:
        """The pairs of modes with a boundary between them, each as ``(lower mode, higher mode)``."""
        types: set[tuple[int, int]] = set()
        for a, b, _ in self.pairs.types() if self.pairs else ():
            lo, hi = sorted((self.present[a], self.present[b]))
            types.add((lo, hi))
        return types

    def boundary_count(self, mode_a: int, mode_b: int) -> int:
        """Boundary pairs between ``mode_a`` and ``mode_b`` (0 when the search did not meet both)."""
        if self.pairs is None or mode_a not in self.present or mode_b not in self.present:
            return 0
        return len(self.pairs.of_type(self.present.index(mode_a), self.present.index(mode_b)))

    def median_pair_distance(self) -> float | None:
        """Median distance between the two runs of a boundary pair (None: no pairs)."""
        return np.median(self.pairs.distance) if self.pairs is not None and len(self.pairs) else None
