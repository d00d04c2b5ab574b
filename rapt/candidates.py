"""Candidate queries and batch selection (Algorithm 1's "p > L random proposals").

Candidate generation is a pluggable component: uniform in the cube by default; chapter 5's
self-righting search generates candidates on estimated constraint manifolds instead
(Algorithm 7).  Any callable ``generator(n, rng, sampler) -> (n, d)`` works.

:func:`select_batch` takes the best-scoring candidates while suppressing near-duplicates,
so a batch of 10,000 does not pile up on the one spot with the highest information.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np
from scipy.spatial import cKDTree

from rapt.errors import InputError
from rapt.parallel import query_workers

if TYPE_CHECKING:  # pragma: no cover
    from rapt.samplers.base import Sampler

__all__ = ["CandidateGenerator", "UniformCandidates", "select_batch"]


class CandidateGenerator(Protocol):
    """Proposes ``n`` unit-cube candidates; may read the sampler's data (``sampler.X``, ``sampler.Y``)."""

    def __call__(self, n: int, rng: np.random.Generator, sampler: Sampler) -> np.ndarray: ...


class UniformCandidates:
    """Uniform random candidates in the unit cube."""

    def __call__(self, n: int, rng: np.random.Generator, sampler: Sampler) -> np.ndarray:
        return rng.random((n, sampler.dim))

    def __repr__(self) -> str:
        return "UniformCandidates()"


def select_batch(
    candidates: np.ndarray, information: np.ndarray, n: int, radius: np.ndarray | float, space: np.ndarray | None = None
) -> np.ndarray:
    """Indices of ``n`` candidates chosen greedily by descending information.

    A candidate is skipped when it lies within ``radius`` (its own radius) of one already
    chosen, measured in ``space`` (the candidates' coordinates in the metric space of the
    search; defaults to ``candidates``).  If suppression leaves fewer than ``n``, the rest
    are filled with the best skipped candidates, so the batch size is always honoured.
    Ties are broken by candidate order, which is seeded, so selection is deterministic.
    """
    information = np.asarray(information, dtype=float)
    p = information.shape[0]
    if n > p:
        raise InputError(f"n: cannot choose {n} from {p} candidates; generate more candidates than the batch size")
    pts = np.asarray(candidates if space is None else space, dtype=float)
    radius = np.broadcast_to(np.asarray(radius, dtype=float), (p,))
    order = np.argsort(-information, kind="stable")
    if not np.any(radius > 0):
        return order[:n]
    tree = cKDTree(pts)
    suppressed = np.zeros(p, dtype=bool)
    chosen: list[int] = []
    start = 0
    chunk = max(2 * n, 256)
    while len(chosen) < n and start < p:
        block = order[start : start + chunk]
        start += chunk
        live = block[~suppressed[block]]
        if live.size == 0:
            continue
        balls = tree.query_ball_point(pts[live], r=radius[live], workers=query_workers(live.size))
        for i, ball in zip(live, balls):
            if suppressed[i]:
                continue
            chosen.append(int(i))
            suppressed[ball] = True
            if len(chosen) == n:
                break
    if len(chosen) < n:
        taken = np.zeros(p, dtype=bool)
        taken[chosen] = True
        rest = order[~taken[order]][: n - len(chosen)]
        chosen.extend(int(i) for i in rest)
    return np.asarray(chosen, dtype=np.int64)
