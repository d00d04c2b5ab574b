"""Performance modes (section 3.3) and boundary pairs by the mutual-nearest-neighbour rule: hand-built cases and errors."""

import numpy as np
import pytest

import rapt
from rapt.boundaries import boundary_pairs, mutual_pairs
from rapt.modes import performance_modes
from rapt.testfunctions.noise import GlobalNoise
from rapt.testfunctions.shapes import Plates2D


def test_discrete_modes_are_label_combinations():
    Y = np.array([[0, 1], [1, 1], [0, 1], [1, 0], [1, 1]], dtype=float)
    labels = performance_modes(Y)
    assert labels.tolist() == [0, 2, 0, 1, 2]  # (0,1) < (1,0) < (1,1)


def test_continuous_modes_by_mean_shift():
    rng = np.random.default_rng(0)
    Y = np.concatenate(
        [
            rng.normal(0.0, 0.01, (200, 2)),
            rng.normal(1.0, 0.01, (300, 2)),
            np.column_stack([rng.normal(0.0, 0.01, 100), rng.normal(1.0, 0.01, 100)]),
        ]
    )
    labels = performance_modes(Y, ["continuous", "continuous"], bandwidth=0.2)
    assert np.bincount(labels).tolist() == [200, 100, 300]
    assert performance_modes(np.full((10, 1), 3.5), ["continuous"]).tolist() == [0] * 10


def test_mixed_modes_combine_labels_and_clusters():
    Y = np.array([[0, 0.0], [0, 1.0], [1, 0.0], [1, 0.02], [1, 1.0]])
    assert performance_modes(Y, ["binary", "continuous"], bandwidth=0.2).tolist() == [0, 1, 2, 2, 3]


def test_mode_errors():
    with pytest.raises(ValueError, match="Y: no samples"):
        performance_modes(np.empty((0, 2)))
    with pytest.raises(ValueError, match="row 1 has NaN"):
        performance_modes(np.array([[0.0], [np.nan]]))
    with pytest.raises(ValueError, match="bandwidth"):
        performance_modes(np.zeros((3, 1)), bandwidth=0)


def test_mutual_nearest_neighbour_rule_hand_built():
    #   mode 0: a=0.0, b=0.5          mode 1: c=0.6, d=1.0
    # a's nearest in mode 1 is c, c's nearest in mode 0 is b -> (a, c) is not mutual
    X = np.array([[0.0], [0.5], [0.6], [1.0]])
    labels = np.array([0, 0, 1, 1])
    i, j, d = mutual_pairs(X, labels)
    assert list(zip(i.tolist(), j.tolist())) == [(1, 2)]
    assert d == pytest.approx([0.1])


def test_pairs_are_symmetric_under_relabelling_and_sorted():
    rng = np.random.default_rng(1)
    X = rng.random((400, 2))
    Y = Plates2D()(X)
    a = boundary_pairs(X, Y)
    # swapping mode names must give the same set of pairs
    b = boundary_pairs(X, labels=(4 - Y[:, 0]).astype(int))
    assert {frozenset(p) for p in zip(a.i, a.j)} == {frozenset(p) for p in zip(b.i, b.j)}
    assert np.all(np.diff(a.distance) >= 0)
    assert np.all(a.mode_i < a.mode_j)
    assert np.all(a.labels[a.i] == a.mode_i) and np.all(a.labels[a.j] != a.labels[a.i])


def test_thresholds_d_eps_and_quantile():
    rng = np.random.default_rng(2)
    X = rng.random((2000, 2))
    Y = Plates2D()(X)
    every = boundary_pairs(X, Y)
    near = boundary_pairs(X, Y, d_eps=0.02)
    assert len(near) < len(every) and np.all(near.distance < 0.02)
    q = boundary_pairs(X, Y, quantile=0.2)
    for a, b, n in q.types():
        all_d = every.of_type(a, b).distance
        assert np.all(q.of_type(a, b).distance <= np.quantile(all_d, 0.2))
        assert n == np.sum(all_d <= np.quantile(all_d, 0.2))


def test_single_mode_has_no_boundaries():
    X = np.random.default_rng(0).random((50, 3))
    bp = boundary_pairs(X, np.ones((50, 1)))
    assert len(bp) == 0 and bp.types() == []


def test_noise_filter_flags_isolated_endpoints():
    system = GlobalNoise(Plates2D(), 0.05, seed=1)
    study = rapt.search(system, [(0, 1)] * 2, 3000, seed=0, output_types=("categorical",))
    bp = boundary_pairs(study.X, study.Y, cluster_eps=0.05, min_samples=5)
    dist = Plates2D().boundary_distance(study.X)[:, 0]
    true = (dist[bp.i] < 0.03) & (dist[bp.j] < 0.03)
    assert bp.likely_noise[~true].mean() > 0.9
    assert bp.likely_noise[true].mean() < bp.likely_noise[~true].mean() - 0.3


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(X=np.empty((0, 2)), Y=np.empty((0, 1))), "X: expected a non-empty"),
        (dict(X=np.zeros((3, 2)), Y=np.zeros((2, 1))), "Y: expected 3 score rows"),
        (dict(X=np.zeros((3, 2))), "give exactly one"),
        (dict(X=np.zeros((3, 2)), Y=np.zeros((3, 1)), quantile=1.5), "quantile"),
        (dict(X=np.zeros((3, 2)), Y=np.zeros((3, 1)), d_eps=-1.0), "d_eps"),
        (dict(X=np.zeros((3, 2)), Y=np.zeros((3, 1)), weights=np.ones(3)), "weights"),
    ],
)
def test_boundary_pair_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        boundary_pairs(**kwargs)


def test_pair_differences_and_type_importance():
    from rapt.boundaries import pair_differences
    from rapt.importance import boundary_type_importance, output_importance

    rng = np.random.default_rng(3)
    X = rng.random((3000, 3))
    # mode 0/1 split on x0, mode 1/2 split on x2
    labels = np.where(X[:, 0] < 0.5, 0, np.where(X[:, 2] < 0.5, 1, 2))
    bp = boundary_pairs(X, labels=labels, quantile=0.5)
    diff = pair_differences(X, bp)
    assert diff.shape == (len(bp), 3)
    assert np.allclose(np.abs(diff).sum(axis=1) > 0, True)
    sel01 = (bp.mode_i == 0) & (bp.mode_j == 1)
    assert np.median(np.abs(diff[sel01, 0])) > np.median(np.abs(diff[sel01, 1]))
    physical = pair_differences(X * [10, 1, 1], bp, bounds=[(0, 10), (0, 1), (0, 1)])
    assert np.allclose(physical, diff)
    vi = boundary_type_importance(X, labels, [(0, 1), (1, 2)])
    assert vi[(0, 1)].argmax() == 0 and vi[(1, 2)].argmax() == 2
    Y = np.column_stack([X[:, 1] > 0.3, X[:, 2]])
    oi = output_importance(X, Y, ["binary", "continuous"])
    assert oi.shape == (2, 3) and oi[0].argmax() == 1 and oi[1].argmax() == 2


def test_small_mean_shift_partitions_like_scikit_learn():
    from sklearn.cluster import MeanShift
    from sklearn.metrics import adjusted_rand_score

    from rapt.modes import _small_mean_shift

    rng = np.random.default_rng(7)
    scores = []
    for _ in range(30):
        k = rng.integers(1, 4)
        centres = rng.random((k, 3))
        Z = np.vstack([c + 0.03 * rng.standard_normal((rng.integers(3, 30), 3)) for c in centres])
        ours = _small_mean_shift(Z, 0.2)
        ref = MeanShift(bandwidth=0.2).fit(Z).labels_
        scores.append(adjusted_rand_score(ref, ours))
    assert np.mean(scores) > 0.97 and np.min(scores) > 0.8


def test_mean_shift_of_many_rows_fits_a_subset_and_assigns_every_row():
    from rapt.modes import MEAN_SHIFT_MAX_FIT, mean_shift_normalised

    rng = np.random.default_rng(3)
    centres = np.array([[0.1] * 5, [0.5] * 5, [0.9] * 5])
    truth = rng.integers(0, 3, 3 * MEAN_SHIFT_MAX_FIT)
    Z = centres[truth] + 0.01 * rng.standard_normal((truth.size, 5))
    labels = mean_shift_normalised(Z, 0.2)
    assert labels.shape == truth.shape and np.unique(labels).size == 3
    assert all(np.unique(labels[truth == k]).size == 1 for k in range(3))  # every row with its blob
    np.testing.assert_array_equal(labels, mean_shift_normalised(Z, 0.2))  # seeded subset: deterministic
