"""The record of one self-righting search: every state it evaluated and what became of it.

Grid and adaptive searches (:mod:`planner.selfright.search`) both end in a
:class:`SelfRightStudy`, so the graph, the figures of merit and the outputs are built the
same way whichever search ran.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.selfright.space import row_keys
from rapt.manifold import angular_embedding
from sim.robots import Robot

__all__ = ["SelfRightStudy"]


@dataclass
class SelfRightStudy:
    """Every evaluated state of one search, in unit-cube coordinates of :func:`~planner.selfright.space.space_bounds`."""

    robot: Robot
    slope: float  # degrees
    method: str
    bounds: np.ndarray
    n_free: int
    X: np.ndarray  # (N, d) starting states
    stable: np.ndarray
    rest: np.ndarray  # (N, d), NaN rows where it rolls away
    energy: np.ndarray
    faces: list  # per state: (k, b) valid body angles, unit cube
    queries: int
    seconds: float
    ids: np.ndarray  # (N,) face identity of each starting state
    rest_ids: np.ndarray  # (N,) face identity of each resting state (-1: none)
    face_ids: list  # per state: (k,) identities of ``faces``
    resolution: float | None = None  # grid spacing, radians (grid studies only)
    # grid studies: points per joint axis, and whether each axis is a full turn (its ends meet)
    grid_shape: tuple[int, ...] | None = None
    grid_periodic: tuple[bool, ...] | None = None
    # adaptive studies: the search's settings and how it ended
    r_min_deg: float | None = None  # boundary resolution, degrees
    r_max_deg: float | None = None  # interior resolution, degrees (None: the 10° default of ``d_max``)
    whole_hulls: bool | None = None  # every face of each queried joint state was labelled
    stopped_by_resolution: bool | None = None  # the resolution cut-offs ended the search, not the budget
    search_queries: int | None = None  # queries the search spent (the rest went to refinement)
    refine_queries: int | None = None
    refine_rounds: int | None = None
    joint_states: int | None = None  # distinct joint states queried

    def embed(self, U: np.ndarray) -> np.ndarray:
        return angular_embedding(U, self.bounds)

    def known_states(self, with_ids: bool = False):
        """``X^Z``: every hull face of every evaluated joint state, each once (unit cube); and their identities."""
        counts = np.array([len(f) for f in self.faces])
        K = np.column_stack([np.repeat(self.X[:, : self.n_free], counts, axis=0), np.concatenate(self.faces)])
        _, first = np.unique(row_keys(K), return_index=True)
        first = np.sort(first)
        if not with_ids:
            return K[first]
        return K[first], np.concatenate(self.face_ids)[first]

    def extra_states(self, with_ids: bool = False, known: tuple | None = None):
        """Known states that were not themselves evaluated (Algorithm 8 labels them by nearest neighbour).

        ``known``: :meth:`known_states` ``(with_ids=True)`` when the caller already has it.
        """
        K, ids = self.known_states(with_ids=True) if known is None else known
        new = ~np.isin(row_keys(K), row_keys(self.X))
        if not with_ids:
            return K[new]
        return K[new], ids[new]
