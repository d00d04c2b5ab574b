"""LOLA-Voronoi: its Voronoi volumes, local gradients and neighbourhoods on known cases, and where it samples."""

from __future__ import annotations

import numpy as np
import pytest

import rapt
from rapt.samplers.lola_voronoi import LolaVoronoiSampler, lola_gradients, neighbourhood_score, voronoi_volumes


def test_voronoi_volumes_of_a_regular_grid_are_equal_within_monte_carlo_error():
    g = (np.arange(5) + 0.5) / 5  # cell centres: every Voronoi cell is a 0.2 x 0.2 square
    X = np.array(np.meshgrid(g, g)).reshape(2, -1).T
    T = np.random.default_rng(0).random((200_000, 2))
    V, owner, dist = voronoi_volumes(X, T)
    sigma = np.sqrt(0.04 * 0.96 / len(T))
    assert V.sum() == pytest.approx(1.0)
    assert np.all(np.abs(V - 1 / 25) < 5 * sigma)
    assert np.all(dist <= np.sqrt(2) * 0.1 + 1e-12)  # no test point is farther than a cell's half-diagonal


def test_the_gradient_of_a_linear_function_is_recovered_exactly_with_no_nonlinearity():
    rng = np.random.default_rng(1)
    X = rng.random((30, 3))
    A = np.array([[1.0, -2.0], [0.5, 0.0], [-3.0, 4.0]])  # two outputs
    F = X @ A + np.array([0.3, -1.0])
    hood = np.array([np.argsort(np.linalg.norm(X - x, axis=1))[1:7] for x in X])
    grad, nonlinearity = lola_gradients(X, F, hood)
    assert np.allclose(grad, A[None], atol=1e-10)
    assert np.allclose(nonlinearity, 0.0, atol=1e-10)
    _, curved = lola_gradients(X, F + X[:, :1] ** 2, hood)  # a curvature in x0 shows up as nonlinearity
    assert np.all(curved > 1e-6)


def test_the_neighbourhood_score_prefers_close_neighbours_spread_around_the_sample():
    cross = np.array([[0.1, 0], [-0.1, 0], [0, 0.1], [0, -0.1]])
    lopsided = np.array([[0.1, 0], [0.1, 0.01], [0.1, -0.01], [0.09, 0]])
    assert neighbourhood_score(cross) == pytest.approx(10.0)  # R = 1, C = 0.1
    assert neighbourhood_score(cross) > neighbourhood_score(lopsided)
    assert neighbourhood_score(cross) > neighbourhood_score(2 * cross)
    assert neighbourhood_score(np.array([[0.1], [-0.1]])) == pytest.approx(10.0)  # the 1-D ratio
    assert neighbourhood_score(np.vstack([cross[:3], [[0, 0]]])) == 0.0  # a duplicate of the sample


def step(X: np.ndarray) -> np.ndarray:
    """A mode change along x = 0.7; nothing else varies."""
    return (X[:, 0] > 0.7).astype(float)


def _near_step_share(method: str, seed: int) -> float:
    study = rapt.search(step, [(0.0, 1.0)] * 2, 400, method=method, batch_size=50, seed=seed)
    return float(np.mean(np.abs(study.X[:, 0] - 0.7) < 0.05))


def test_it_samples_the_nonlinear_region_more_than_sobol():
    lola = np.mean([_near_step_share("lola-voronoi", s) for s in (0, 1)])
    sobol = np.mean([_near_step_share("sobol", s) for s in (0, 1)])
    assert sobol == pytest.approx(0.1, abs=0.03)
    assert lola > 2.5 * sobol


def _asks(labels: np.ndarray, seed: int = 3) -> np.ndarray:
    s = LolaVoronoiSampler(2, seed=seed, output_types=["categorical"])
    X = np.random.default_rng(5).random((60, 2))
    s.tell(X, labels[(X[:, 0] > 0.5).astype(int) + (X[:, 1] > 0.5).astype(int)])
    return s.ask(20)


def test_asks_are_deterministic_and_ignore_the_values_of_mode_labels():
    a = _asks(np.array([0.0, 1.0, 2.0]))
    assert np.array_equal(a, _asks(np.array([0.0, 1.0, 2.0])))
    assert np.array_equal(a, _asks(np.array([9.0, 5.0, 7.0])))  # one vs rest: label values carry no order
    assert not np.array_equal(a, _asks(np.array([0.0, 1.0, 2.0]), seed=4))
    assert len(np.unique(a, axis=0)) == 20


def test_a_batch_larger_than_the_cells_puts_extra_points_in_the_top_cells():
    s = LolaVoronoiSampler(2, seed=0)
    X = np.random.default_rng(2).random((8, 2))
    s.tell(X, step(X))
    Q = s.ask(30)
    assert Q.shape == (30, 2) and len(np.unique(Q, axis=0)) == 30
    assert s.last_scores is not None and len(s.last_scores) == 8


@pytest.mark.parametrize("dim", [2, 3])
def test_the_fast_swap_scores_equal_the_scores_of_the_swapped_neighbourhoods(dim):
    from scipy.spatial import cKDTree

    from rapt.samplers.lola_voronoi import _swap_scores, _swapped

    X = np.random.default_rng(dim).random((40, dim))
    m, k = 2 * dim, 6 * dim
    dist, cand = cKDTree(X).query(X, k=k + 1)
    dist, cand = dist[:, 1:], cand[:, 1:]
    pos = np.array([np.random.default_rng(i).permutation(k - 1)[:m] for i in range(40)])
    P = X[cand]
    between = np.linalg.norm(P[:, :, None, :] - P[:, None, :, :], axis=-1)
    direct = neighbourhood_score(_swapped(X, cand, pos, k - 1) - X[:, None, None, :])
    assert np.allclose(_swap_scores(between, dist, pos, k - 1), direct)
