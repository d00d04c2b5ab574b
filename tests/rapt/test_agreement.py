"""Per-type boundary recall and precision: what mode accuracy hides."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.agreement import agreement, boundary_types
from rapt.errors import InputError


def _square(n=1500, seed=0):
    X = np.random.default_rng(seed).random((n, 2))
    truth = (X[:, 0] > 0.5).astype(int)
    truth[np.hypot(X[:, 0] - 0.25, X[:, 1] - 0.5) < 0.12] = 2  # a rare mode: a small disc
    return X, truth


def test_a_perfect_surrogate_recalls_every_type():
    X, truth = _square()
    got = boundary_types(X, truth, truth, touching=(2,))
    assert {(0, 1), (0, 2), "all", "touching"} <= set(got)
    for t in got.values():
        assert t.recall == 1.0 and t.precision == 1.0 and t.system_pairs == t.surrogate_pairs > 0


def test_a_surrogate_that_misses_the_rare_mode_scores_high_on_modes_and_zero_on_its_boundary():
    X, truth = _square()
    blind = (X[:, 0] > 0.5).astype(int)  # right everywhere but the disc
    assert agreement(X, truth, blind, 3).mode_accuracy > 0.94
    got = boundary_types(X, truth, blind, touching=(2,))
    assert got[(0, 2)].recall == 0.0 and got["touching"].recall == 0.0 and got[(0, 2)].surrogate_pairs == 0
    assert got[(0, 1)].recall > 0.95 and got[(0, 1)].precision == 1.0
    assert got["all"].recall < 0.6  # the disc's pairs are most of the boundary pairs


def test_a_shifted_boundary_loses_recall_where_it_moved():
    X, truth = _square()
    shifted = truth.copy()
    shifted[(X[:, 0] > 0.49) & (X[:, 0] <= 0.5) & (truth == 0)] = 1  # the 0/1 boundary moved by 0.01
    got = boundary_types(X, truth, shifted)
    assert 0.0 < got[(0, 1)].recall < 0.5  # pairs straddling 0.45..0.5 now have a wrong end (pairs are close)
    assert got[(0, 2)].recall == 1.0


def test_labels_must_match_the_states():
    X, truth = _square(100)
    with pytest.raises(InputError, match="one label per scenario"):
        boundary_types(X, truth, truth[:-1])
