"""Where the expert is asked next: the learner's boundary pairs (rare types first) and its doubts."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.errors import InputError
from rapt.imitation.queries import boundary_queries, pair_queries


def _space(n=2000, seed=0):
    X = np.random.default_rng(seed).random((n, 2))
    labels = (X[:, 0] > 0.5).astype(int)
    labels[np.hypot(X[:, 0] - 0.25, X[:, 1] - 0.5) < 0.08] = 2  # a rare mode (2 % of the space)
    return X, labels


def test_pairs_take_turns_by_type_rarest_first_and_cross_a_boundary():
    X, labels = _space()
    pairs = pair_queries(X, labels, 20)
    assert pairs.shape == (20, 2)
    kinds = [tuple(sorted((labels[i], labels[j]))) for i, j in pairs]
    assert all(a != b for a, b in kinds)  # every pair crosses a boundary
    assert kinds[0] == (0, 2)  # the rare disc's boundary comes first ...
    assert kinds.count((0, 2)) >= 8  # ... and gets as many turns as the common one, not its 2 % share
    assert np.unique(pairs).size == pairs.size  # a state is asked once


def test_queries_mix_disagreements_and_both_ends_of_boundary_pairs():
    X, labels = _space()
    previous = labels.copy()
    doubt = np.flatnonzero(X[:, 1] > 0.95)  # the last update labelled a strip differently
    previous[doubt] = 1 - np.minimum(previous[doubt], 1)
    rows = boundary_queries(X, labels, 40, np.random.default_rng(0), previous)
    assert rows.size == np.unique(rows).size == 40
    assert np.sum(np.isin(rows, doubt)) == 20  # half where the updates disagree
    rest = rows[~np.isin(rows, doubt)]
    # the rest are both ends of boundary pairs: each lies next to a state of another label
    d = np.linalg.norm(X[rest][:, None, :] - X[None, :, :], axis=2)
    d[labels[rest][:, None] == labels[None, :]] = np.inf
    assert np.all(d.min(axis=1) < 0.05)
    # uniform draws would put about 2 % in the rare disc; here a good share of the asks lie on its edge
    assert np.mean(labels[rest] == 2) > 0.2


def test_without_boundaries_or_doubts_the_queries_are_random_and_seeded():
    X = np.random.default_rng(1).random((100, 3))
    one = np.zeros(100, dtype=int)
    a = boundary_queries(X, one, 10, np.random.default_rng(5))
    b = boundary_queries(X, one, 10, np.random.default_rng(5))
    assert a.tolist() == b.tolist() and np.unique(a).size == 10
    with pytest.raises(InputError, match="k: expected 0..100"):
        boundary_queries(X, one, 101, np.random.default_rng(0))
