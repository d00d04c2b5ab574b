"""Where to ask the expert next: at the learner's boundary candidates and where learners disagree.

Imitation learning spends expert runs on scenarios; uniformly drawn, they fall where the
learner is already right (most of the space is one mode) and seldom where a rare mode
begins, so the learner is trained least where a boundary search needs it most.  After
the first updates the learner's own adaptive search shows where it places boundaries,
and each of its boundary pairs is a place where both the learner and the expert can be
compared across a flip of behaviour.  Scenarios where the last two updates disagree
are where the learner is still unsure.  Both are cheap to find: the learner, not the
expert, runs the search.

:func:`boundary_queries` is generic: states and labels in, the rows to annotate out.
"""

from __future__ import annotations

import numpy as np

from rapt.boundaries import boundary_pairs
from rapt.errors import InputError

__all__ = ["boundary_queries", "pair_queries"]


#: Pairs longer than this many times the median pair are not boundaries (a third mode lies between).
LONG_PAIR = 3.0


def pair_queries(X: np.ndarray, labels: np.ndarray, pairs: int) -> np.ndarray:
    """Up to ``pairs`` boundary pairs of labelled states ``X`` as (pairs, 2) row indices.

    The types (pairs of labels) take turns, the rarest type first, and each type gives its
    shortest pairs first (the best placed boundary): a rare boundary, such as a collision
    in a mission that mostly succeeds, is asked about as often as the common one.  Mutual
    neighbours of two modes with a third between them are far apart: pairs longer than
    :data:`LONG_PAIR` times the median are skipped.
    """
    X = np.asarray(X, dtype=float)
    labels = np.asarray(labels).reshape(-1)
    if labels.shape[0] != X.shape[0]:
        raise InputError(f"labels: expected {X.shape[0]} labels (one per state), got {labels.shape[0]}")
    found = boundary_pairs(X, labels=labels)
    if len(found):
        found = found.select(found.distance <= LONG_PAIR * np.median(found.distance))
    if len(found) == 0 or pairs <= 0:
        return np.zeros((0, 2), dtype=np.int64)
    by_type = [found.of_type(a, b) for a, b, _ in sorted(found.types(), key=lambda t: (t[2], t[0], t[1]))]
    out: list[tuple[int, int]] = []
    used: set[int] = set()
    depth = 0
    while len(out) < pairs and any(depth < len(p) for p in by_type):
        for p in by_type:
            if depth < len(p) and len(out) < pairs:
                i, j = int(p.i[depth]), int(p.j[depth])
                if i not in used and j not in used:  # a state annotated once
                    out.append((i, j))
                    used.update((i, j))
        depth += 1
    return np.asarray(out, dtype=np.int64).reshape(-1, 2)


def boundary_queries(
    X: np.ndarray,
    labels: np.ndarray,
    k: int,
    rng: np.random.Generator,
    previous: np.ndarray | None = None,
    disagreement_share: float = 0.5,
) -> np.ndarray:
    """``k`` distinct rows of ``X`` to annotate: both ends of boundary pairs and rows of disagreement.

    ``labels`` are the current learner's labels of the states ``X`` (its own search);
    ``previous`` the last learner's labels of the same states, if any.  Up to a
    ``disagreement_share`` of ``k`` rows are drawn (seeded by ``rng``) where the two
    disagree; the rest are both ends of :func:`pair_queries`; what is still missing comes from
    the other kind, then from random rows.
    """
    n = np.asarray(X).shape[0]
    if not 0 <= k <= n:
        raise InputError(f"k: expected 0..{n} rows to annotate, got {k!r}")
    if not 0.0 <= disagreement_share <= 1.0:
        raise InputError(f"disagreement_share: expected a share in [0, 1], got {disagreement_share!r}")
    differ = np.zeros(n, dtype=bool) if previous is None else np.asarray(previous) != np.asarray(labels)
    doubt = rng.permutation(np.flatnonzero(differ))
    chosen = list(doubt[: int(round(disagreement_share * k))])
    taken = set(chosen)
    for i, j in pair_queries(X, labels, k):
        for r in (int(i), int(j)):
            if len(chosen) < k and r not in taken:
                chosen.append(r)
                taken.add(r)
    for r in list(doubt) + list(rng.permutation(n)):
        if len(chosen) >= k:
            break
        if int(r) not in taken:
            chosen.append(int(r))
            taken.add(int(r))
    return np.asarray(chosen, dtype=np.int64)
