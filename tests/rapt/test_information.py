"""The information metrics (eqs. 3.4-3.8), tree importances and batch selection, against hand-computed values."""

import numpy as np
import pytest

from rapt.candidates import select_batch
from rapt.importance import importance_weights, tree_importance
from rapt.information import gpr_information, neighbour_variance, nndv_information, unalikeability


def test_unalikeability_hand_computed():
    labels = np.array(
        [
            [0, 0, 0, 0],  # all alike
            [0, 1, 2, 3],  # all different
            [0, 0, 1, 1],  # pairs differing: 8 of 12 ordered pairs
            [2, 2, 2, 5],  # 6 of 12
        ]
    )
    u = unalikeability(labels, 6)
    assert u == pytest.approx([0.0, 1.0, 8 / 12, 6 / 12])


def test_unalikeability_matches_pairwise_definition():
    rng = np.random.default_rng(0)
    labels = rng.integers(0, 4, size=(200, 7))
    brute = np.array([sum(row[i] != row[j] for i in range(7) for j in range(7) if i != j) / (7 * 6) for row in labels])
    assert unalikeability(labels) == pytest.approx(brute)


def test_unalikeability_rejects_bad_shapes():
    with pytest.raises(ValueError, match="labels"):
        unalikeability(np.array([1, 2, 3]))
    with pytest.raises(ValueError, match="at least 2"):
        unalikeability(np.array([[1], [2]]))


def test_nndv_and_gpr_formulas():
    assert neighbour_variance(np.array([[0.0, 1.0], [2.0, 2.0]])) == pytest.approx([0.25, 0.0])
    assert nndv_information([0.25, 0.0], [0.1, 0.2], g=2, v=1) == pytest.approx([0.00625, 0.0])
    assert nndv_information([0.0], [0.2], g=1, v=1, floor=0.1) == pytest.approx([0.02])
    assert gpr_information([3.0], [0.5], g=1, v=2) == pytest.approx([0.75])


def test_tree_importance_finds_the_contributing_inputs():
    rng = np.random.default_rng(1)
    X = rng.random((3000, 5))
    y = (X[:, 1] + 0.3 * X[:, 3] > 0.8).astype(int)
    vi = tree_importance(X, y, "categorical", random_state=0)
    assert vi.sum() == pytest.approx(1.0)
    assert vi.argmax() == 1
    assert vi[3] > vi[0] and vi[3] > vi[2] and vi[3] > vi[4]
    w = importance_weights(vi)
    assert w.max() == 1.0 and w[1] == 1.0
    assert tree_importance(X, np.zeros(3000), "categorical").tolist() == [0.0] * 5
    assert importance_weights(np.zeros(3)).tolist() == [1.0, 1.0, 1.0]


def test_select_batch_suppresses_near_duplicates():
    cand = np.array([[0.5, 0.5], [0.501, 0.5], [0.9, 0.9], [0.1, 0.1]])
    info = np.array([1.0, 0.99, 0.5, 0.1])
    assert select_batch(cand, info, 2, radius=0.0).tolist() == [0, 1]
    assert select_batch(cand, info, 2, radius=0.05).tolist() == [0, 2]
    # not enough separated candidates: filled with the best suppressed ones
    assert sorted(select_batch(cand, info, 4, radius=0.05).tolist()) == [0, 1, 2, 3]
    with pytest.raises(ValueError, match="candidates"):
        select_batch(cand, info, 5, radius=0.0)
