"""Algorithms 6-7 (rapt.manifold): the manifold-constrained sampler on toy systems, and the angle embedding."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.manifold import ManifoldSampler, angular_embedding, manifold_search


def test_manifold_sampler_learns_from_projected_states_and_stops_at_resolution():
    """Valid states: phi in {0.25, 0.75} (a projection snaps phi to the nearer); stable iff t < 0.5 on the lower one."""
    bounds = [[0.0, np.pi], [0.0, np.pi]]

    def system(Q):
        X = Q.copy()
        X[:, 1] = np.where(Q[:, 1] < 0.5, 0.25, 0.75)
        y = ((X[:, 1] > 0.5) | (X[:, 0] < 0.5)).astype(float)
        return X, y, [np.array([[0.25], [0.75]])] * len(X)

    s = ManifoldSampler(1, bounds, seed=1, r_min=np.radians(0.5), r_max=np.radians(5.0), n_initial=30)
    manifold_search(system, s, budget=3000, batch_size=20)
    assert s.done and s.n_told < 3000  # the cut-offs ended the search
    assert set(np.round(s.X[:, 1], 6)) == {0.25, 0.75}  # it only ever learned valid states
    t_on_boundary = s.X[(s.X[:, 1] == 0.25), 0]
    gap = np.abs(t_on_boundary - 0.5).min() * np.pi
    assert gap < np.radians(1.0)  # refined to the boundary resolution
    # the boundary is sampled far more densely than the interior
    near = np.mean(np.abs(t_on_boundary - 0.5) < 0.05)  # share of samples in 10 % of the length
    assert near / 0.1 > 1.5 * (1 - near) / 0.9
    # deterministic under its seed
    s2 = ManifoldSampler(1, bounds, seed=1, r_min=np.radians(0.5), r_max=np.radians(5.0), n_initial=30)
    manifold_search(system, s2, budget=3000, batch_size=20)
    assert np.array_equal(s.X, s2.X)


def test_angular_embedding_is_periodic():
    b = [[-np.pi, np.pi]]
    e = angular_embedding(np.array([[0.0], [1.0], [0.5]]), b)
    assert np.allclose(e[0], e[1]) and np.allclose(e[2], [1.0, 0.0])
    # chord length ~ angle for small differences
    u = np.array([[0.5], [0.5 + 0.01 / (2 * np.pi)]])
    d = np.linalg.norm(np.diff(angular_embedding(u, b), axis=0))
    assert d == pytest.approx(0.01, rel=1e-4)


def test_whole_hull_sampling_labels_every_face_of_distinct_joint_states():
    """Two faces per t; a whole-hull system labels both, and each is one query."""
    bounds = [[0.0, np.pi], [0.0, np.pi]]
    faces = np.array([[0.25], [0.75]])

    def system(Q):
        t = np.unique(Q[:, 0])
        X = np.column_stack([np.repeat(t, 2), np.tile(faces[:, 0], len(t))])
        y = ((X[:, 1] > 0.5) | (X[:, 0] < 0.5)).astype(float)
        ids = np.where(X[:, 1] > 0.5, 2, 1)
        return X, y, [faces] * len(X), ids, [np.array([1, 2])] * len(X)

    s = ManifoldSampler(1, bounds, seed=2, r_min=np.radians(0.5), r_max=np.radians(5.0), n_initial=20, whole_hulls=True)
    manifold_search(system, s, budget=400, batch_size=20)
    assert s.done and s.n_told < 400 and s.n_told % 2 == 0  # the cut-offs ended it; faces come in whole hulls
    t = s.X[:, 0]
    assert len(np.unique(t)) == s.n_told // 2  # no joint state asked twice
    assert np.abs(t - 0.5).min() * np.pi < np.radians(1.0)  # refined to the boundary on face 1
    with pytest.raises(ValueError, match="whole_hulls"):
        ManifoldSampler(0, [[0.0, 1.0]], whole_hulls=True)


def test_a_face_not_asked_at_a_neighbour_is_not_read_as_gone():
    """Faces 1 and 2 exist at every t and face 1 is stable everywhere.  At t = 0.5 only face 2 was asked
    (as the transition refinement asks single faces): face 1 is still there, so the search must see no
    boundary on it; at t = 0.6, where face 1 is truly gone, it must."""
    bounds = [[0.0, np.pi], [0.0, np.pi]]
    faces = np.array([[0.25], [0.75]])
    both = np.array([1, 2])
    s = ManifoldSampler(1, bounds, seed=0, n_initial=2, whole_hulls=True)
    t = np.array([0.1, 0.1, 0.9, 0.9])
    s.tell(np.column_stack([t, np.tile(faces[:, 0], 2)]), np.ones(4), [faces] * 4, np.tile(both, 2), [both] * 4)
    s.tell(np.array([[0.5, 0.75]]), np.ones(1), [faces], np.array([2]), [both])  # face 2 alone
    at = np.array([[0.45, 0.25]])
    assert s.hull_information(at, np.array([1]))[1][0] == 0.0
    s.tell(np.array([[0.6, 0.75]]), np.ones(1), [faces[1:]], np.array([2]), [np.array([2])])  # face 1 gone
    assert s.hull_information(np.array([[0.58, 0.25]]), np.array([1]))[1][0] > 0.0


def test_outcomes_bracket_a_stable_island_narrower_than_the_interior_resolution():
    """Face 1 is stable only on t in [0.48, 0.52] (7°) and tips to 10 below it, to 20 above; face 2 is stable.

    Every sample off the island reads "unstable" on face 1, so the label variance cannot see
    it between two samples 20° apart; where they tip can, and the search then finds the island.
    """
    bounds = [[0.0, np.pi], [0.0, np.pi]]
    faces = np.array([[0.25], [0.75]])

    def system(Q, with_outcomes=True):
        t = np.unique(Q[:, 0])
        X = np.column_stack([np.repeat(t, 2), np.tile(faces[:, 0], len(t))])
        y = ((X[:, 1] > 0.5) | (np.abs(X[:, 0] - 0.5) <= 0.02)).astype(float)
        ids = np.where(X[:, 1] > 0.5, 2, 1)
        rest = np.where(y > 0, ids, np.where(X[:, 0] < 0.5, 10, 20)).astype(float)
        out = (X, y, [faces] * len(X), ids, [np.array([1, 2])] * len(X))
        return out + (rest,) if with_outcomes else out

    def sampler(seed):
        return ManifoldSampler(
            1, bounds, seed=seed, r_min=np.radians(0.5), r_max=np.radians(20.0), n_initial=6, whole_hulls=True
        )

    # σ at t = 0.5 on face 1, between samples 36° apart that all read unstable there
    told = np.array([[0.1, 0.25], [0.3, 0.25], [0.7, 0.25], [0.9, 0.25]])
    plain, steered = sampler(0), sampler(0)
    plain.tell(*system(told, with_outcomes=False))
    steered.tell(*system(told))
    at = np.array([[0.5, 0.25]])
    assert plain.hull_information(at, np.array([1]))[1][0] == 0.0
    assert steered.hull_information(at, np.array([1]))[1][0] > 0.0
    with pytest.raises(ValueError, match="outcomes"):
        sampler(0).tell(*system(told)[:5], outcomes=np.zeros(3))
    # the search, told where states tip, samples the island and resolves both its edges on every
    # seed; without, it finds the island only where a sample happens to land on it
    found_blind = 0
    for seed in range(8):
        s = sampler(seed)
        manifold_search(system, s, budget=200, batch_size=4)
        on_face = s.X[:, 1] == 0.25
        assert (on_face & (s.Y[:, 0] > 0)).any(), f"seed {seed}: island not found"
        t = s.X[on_face, 0]
        for edge in (0.48, 0.52):
            assert np.abs(t - edge).min() * np.pi < np.radians(1.0), f"seed {seed}: edge {edge} not resolved"
        blind = sampler(seed)
        manifold_search(lambda Q: system(Q, with_outcomes=False), blind, budget=200, batch_size=4)
        found_blind += bool(((blind.X[:, 1] == 0.25) & (blind.Y[:, 0] > 0)).any())
    assert found_blind <= 4
