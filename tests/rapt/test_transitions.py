"""Algorithm 8 (rapt.transitions) on hand-built state sets, and Gabriel graphs."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.transitions import gabriel_graph, transition_graph


def brute_gabriel(X):
    edges = set()
    for a in range(len(X)):
        for b in range(a + 1, len(X)):
            mid, r = (X[a] + X[b]) / 2, np.linalg.norm(X[a] - X[b]) / 2
            d = np.linalg.norm(X - mid, axis=1)
            d[[a, b]] = np.inf
            if not (d < r).any():
                edges.add((a, b))
    return edges


@pytest.mark.parametrize("dim", [2, 3])
def test_gabriel_graph_matches_brute_force(dim):
    X = np.random.default_rng(dim).random((120, dim))
    i, j = gabriel_graph(X, 10.0)
    assert set(zip(i.tolist(), j.tolist())) == brute_gabriel(X)
    i2, j2 = gabriel_graph(X, 0.1)  # the length cap only removes edges
    L = np.linalg.norm(X[i2] - X[j2], axis=1)
    assert np.all(L <= 0.1) and set(zip(i2.tolist(), j2.tolist())) == {
        e for e in brute_gabriel(X) if np.linalg.norm(X[e[0]] - X[e[1]]) <= 0.1
    }


def two_manifolds():
    """Free coordinate t in [0, 1]; manifolds A (phi = 0) and B (phi = 1), one unit apart.

    A is stable except on 0.3 <= t < 0.6, where it falls onto B losing energy 1 + t;
    B is stable for t > 0.2 and falls onto A below, losing energy 2.
    """
    t = np.round(np.arange(0, 1.0001, 0.05), 10)
    X = np.concatenate([np.column_stack([t, np.zeros_like(t)]), np.column_stack([t, np.ones_like(t)])])
    stable = np.concatenate([(t < 0.3) | (t >= 0.6), t > 0.2])
    rest = X.copy()
    rest[: len(t)][~stable[: len(t)], 1] = 1.0
    rest[len(t) :][~stable[len(t) :], 1] = 0.0
    energy = np.concatenate([np.where(stable[: len(t)], 0.0, 1.0 + t), np.where(stable[len(t) :], 0.0, 2.0)])
    return t, X, stable, rest, energy


def test_transition_graph_on_a_hand_built_state_set():
    t, X, stable, rest, energy = two_manifolds()
    g = transition_graph(X, stable, rest, energy, max_edge=0.12)
    # nodes: A below the band, A above it, B above 0.2 (the largest)
    assert g.n_nodes == 3
    node = lambda tt, phi: int(g.node_of([[tt, phi]])[0])  # noqa: E731
    a_low, a_high, b = node(0.1, 0), node(0.8, 0), node(0.5, 1)
    assert len({a_low, a_high, b}) == 3 and b == 0
    assert g.labels[np.flatnonzero((X[:, 1] == 0) & (X[:, 0] >= 0.3) & (X[:, 0] < 0.6))].max() == -1
    edges = {
        (int(s), int(d)): (float(e), int(w), float(L))
        for s, d, e, w, L in zip(
            g.edges["src"], g.edges["dst"], g.edges["energy"], g.edges["witness"], g.edges["length"]
        )
    }
    # A's lower region tips onto B from t = 0.3 (energy 1.3); the upper one from t = 0.55 (energy 1.55);
    # B tips onto A's lower region from t = 0.2; duplicates keep their lowest energy
    assert set(edges) == {(a_low, b), (a_high, b), (b, a_low)}
    assert edges[(a_low, b)][0] == pytest.approx(1.3)
    assert edges[(a_high, b)][0] == pytest.approx(1.55)
    assert edges[(b, a_low)][0] == pytest.approx(2.0)
    assert all(v[2] == pytest.approx(0.05) for v in edges.values())  # boundary pairs one step apart
    # each pair's other end is the stable state of the source node it was reached from
    P = g.points[g.edges["partner"]]
    assert g.stable[g.edges["partner"]].all() and np.array_equal(g.labels[g.edges["partner"]], g.edges["src"])
    assert np.allclose(np.abs(P[:, 0] - X[g.edges["witness"], 0]), 0.05) and np.allclose(
        P[:, 1], X[g.edges["witness"], 1]
    )
    # only unstable states next to a stable one are transitions (deeper ones cannot be reached without tipping)
    assert sorted(np.round(X[g.all_transitions["witness"], 0], 6).tolist()) == [0.2, 0.3, 0.55]
    # reachability and lowest-energy paths
    cost, _ = g.costs_to(b)
    assert cost[b] == 0 and cost[a_low] == pytest.approx(1.3) and cost[a_high] == pytest.approx(1.55)
    cost, _ = g.costs_to(a_high)
    assert np.isinf(cost[a_low]) and np.isinf(cost[b])
    assert [(int(g.edges["src"][e]), int(g.edges["dst"][e])) for e in g.path(b, a_low)] == [(b, a_low)]
    ok, c = g.outcome(np.array([[0.4, 0.0], [0.9, 1.0]]), a_low)  # an unstable state ends on B, which reaches a_low
    assert ok.all() and c[0] == pytest.approx(2.0) and c[1] == pytest.approx(2.0)


def test_parallel_manifolds_stay_apart_and_extra_states_fill_gaps():
    t, X, stable, rest, energy = two_manifolds()
    # evaluate only every other state of B; the rest are "extra" known states labelled by their nearest neighbour
    keep = np.ones(len(X), dtype=bool)
    keep[len(t) + 1 :: 2] = False
    g = transition_graph(X[keep], stable[keep], rest[keep], energy[keep], X[~keep], max_edge=0.07)
    assert g.n_nodes == 3  # 0.1-spaced evaluated B states connect only through the extra ones
    g2 = transition_graph(X[keep], stable[keep], rest[keep], energy[keep], max_edge=0.07)
    assert g2.n_nodes > 3  # without the extra states, B falls apart
    g3 = transition_graph(X, stable, rest, energy, max_edge=1.5)  # a cap above the gap joins A and B
    assert g3.n_nodes < 3


def test_an_extra_state_guessed_unstable_does_not_hide_a_transition():
    """A's states at t = 0.25 and 0.3 are not evaluated; an extra state at 0.3 takes its label from the nearest
    evaluated one (0.35, unstable).  That guess lies inside the ball of the real boundary pair (0.2 stable,
    0.35 unstable), and if it blocked the pair, A's lower region would have no transition at all."""
    t, X, stable, rest, energy = two_manifolds()
    on_a = X[:, 1] == 0
    gone = on_a & np.isin(np.round(X[:, 0], 6), [0.25, 0.3])
    extra = np.array([[0.3, 0.0]])
    g = transition_graph(X[~gone], stable[~gone], rest[~gone], energy[~gone], extra, max_edge=0.2)
    assert not g.stable[-1] and g.end_node[-1] == int(g.node_of([[0.5, 1.0]])[0])  # still guessed unstable
    a_low, b = int(g.node_of([[0.1, 0.0]])[0]), int(g.node_of([[0.5, 1.0]])[0])
    e = g.edges
    k = np.flatnonzero((e["src"] == a_low) & (e["dst"] == b))
    assert k.size == 1, "A's lower region lost its transition onto B"
    assert X[~gone][e["witness"][k[0]], 0] == pytest.approx(0.35)
    assert g.points[e["partner"][k[0]], 0] == pytest.approx(0.2) and e["length"][k[0]] == pytest.approx(0.15)
    # between two stable states such a guess still stands, as any unstable state does: S1 (0, 0) and S2 (1, 0)
    # span a ball that holds only the guess E (0.5, 0.45), whose nearest evaluated state U (0.5, 0.56) lies outside
    X2 = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.56]])
    g2 = transition_graph(
        X2, np.array([True, True, False]), np.full((3, 2), np.nan), np.zeros(3), np.array([[0.5, 0.45]]), max_edge=2.0
    )
    assert not g2.stable[-1] and g2.labels[0] != g2.labels[1] and g2.n_nodes == 2


def test_face_identities_keep_close_faces_apart_and_continuations_join_a_replaced_face():
    """Three stable faces over t in [0, 1]: A (phi 0) for t < 0.5, replaced by C (phi 0) from t = 0.5; B runs parallel at phi 0.02."""
    t = np.round(np.arange(0, 1.0001, 0.05), 10)
    X = np.concatenate([np.column_stack([t, np.zeros_like(t)]), np.column_stack([t, np.full_like(t, 0.02)])])
    ids = np.concatenate([np.where(t < 0.5, 1, 3), np.full(len(t), 2)])
    stable = np.ones(len(X), dtype=bool)
    energy = np.zeros(len(X))
    plain = transition_graph(X, stable, X, energy, max_edge=0.2)
    assert plain.n_nodes == 1  # body angles alone cannot tell B from A and C
    named = transition_graph(X, stable, X, energy, max_edge=0.2, ids=(ids, ids, np.empty(0)))
    assert named.n_nodes == 3  # A, B, C apart (no continuations without free coordinates)
    joined = transition_graph(X, stable, X, energy, max_edge=0.2, ids=(ids, ids, np.empty(0)), free_dims=1)
    assert joined.n_nodes == 2  # C continues A (A is gone where C is, and vice versa); B stays apart
    assert joined.node_of([[0.2, 0.0]], ids=[1])[0] == joined.node_of([[0.8, 0.0]], ids=[3])[0]
    assert joined.node_of([[0.2, 0.02]], ids=[2])[0] != joined.node_of([[0.2, 0.0]], ids=[1])[0]
    # a continuation must be short: a replaced face far away in the free coordinate is not joined
    far = transition_graph(
        X, stable, X, energy, max_edge=0.2, ids=(ids, ids, np.empty(0)), free_dims=1, continuation_edge=0.01
    )
    assert far.n_nodes == 3


def test_a_continuation_is_blocked_by_a_stable_third_face_between_not_by_an_unstable_one():
    """A (phi 0.01) for t < 0.5 is replaced by C (phi 0) from t = 0.5; a third face D at phi 0.002 coexists with A.

    When D is unstable the robot never rests on it (a split face's other half, say) and A
    continues as C; when D is stable the robot may settle on it on the way, so A and C stay
    apart, as they do for an unknown stretch where neither A nor C exists.
    """
    t = np.round(np.arange(0, 1.0001, 0.05), 10)
    low = t < 0.5
    X = np.concatenate(
        [
            np.column_stack([t[low], np.full(low.sum(), 0.01)]),
            np.column_stack([t[~low], np.zeros((~low).sum())]),
            np.column_stack([t[low], np.full(low.sum(), 0.002)]),
        ]
    )
    ids = np.concatenate([np.full(low.sum(), 1), np.full((~low).sum(), 3), np.full(low.sum(), 4)])
    d = ids == 4

    def graph(d_stable: bool, keep=slice(None)):
        stable = np.where(d, d_stable, True)[keep]
        rest = np.where(stable[:, None], X[keep], np.nan)
        return transition_graph(
            X[keep],
            stable,
            rest,
            np.zeros(len(rest)),
            max_edge=0.2,
            ids=(ids[keep], ids[keep], np.empty(0)),
            free_dims=1,
            continuation_edge=0.15,
        )

    a, c = [[0.2, 0.01]], [[0.8, 0.0]]
    g = graph(False)
    assert g.n_nodes == 1 and g.node_of(a, ids=[1])[0] == g.node_of(c, ids=[3])[0]
    g = graph(True)  # (D, as it happens, continues as C itself)
    assert g.n_nodes == 2 and g.node_of(a, ids=[1])[0] != g.node_of(c, ids=[3])[0]
    # A not known at t = 0.45, where D is: the robot's face there is unknown (maybe an unstable band)
    g = graph(False, ~((ids == 1) & np.isclose(X[:, 0], 0.45)))
    assert g.node_of(a, ids=[1])[0] != g.node_of(c, ids=[3])[0]
