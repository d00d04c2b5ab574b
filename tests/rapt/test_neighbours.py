"""The neighbour graph and the row coding that make sub-boundary trees scale."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rapt.boundaries import graph_mutual_pairs, knn_graph, mutual_pairs
from rapt.scores import infer_output_types, row_codes


@settings(max_examples=60, deadline=None)
@given(
    arrays(
        np.float64,
        st.tuples(st.integers(1, 40), st.integers(1, 6)),
        elements=st.sampled_from([0.0, 1.0, 2.0, -3.0, 0.5, 7.25]),
    )
)
def test_row_codes_number_rows_like_unique(A):
    codes, count = row_codes(A)
    _, expected = np.unique(A, axis=0, return_inverse=True)
    assert count == len(np.unique(A, axis=0))
    assert np.array_equal(codes, expected.reshape(-1))


def test_row_codes_survive_keys_wider_than_64_bits():
    A = np.random.default_rng(0).integers(0, 3, size=(5000, 90)).astype(float)  # 3^90 >> 2^63
    codes, count = row_codes(A)
    _, expected = np.unique(A, axis=0, return_inverse=True)
    assert np.array_equal(codes, expected.reshape(-1)) and count == expected.max() + 1


def test_infer_output_types_vectorised():
    rng = np.random.default_rng(1)
    Y = np.column_stack(
        [
            rng.integers(0, 2, 500),
            rng.integers(0, 5, 500),
            rng.random(500),
            rng.integers(0, 40, 500),
            np.full(500, 3.0),
            rng.integers(-2, 0, 500),
        ]
    )
    assert infer_output_types(Y) == ("binary", "categorical", "continuous", "continuous", "categorical", "categorical")
    Y[0, 0] = np.nan  # NaNs are ignored when guessing
    assert infer_output_types(Y)[0] == "binary"


def _edges(i, j):
    return set(zip(i.tolist(), j.tolist()))


@pytest.mark.parametrize("k", [5, 40])  # the column-comparison path and the per-row sort path
def test_graph_pairs_on_a_complete_graph_equal_exact_mutual_pairs(k):
    rng = np.random.default_rng(2)
    X = rng.random((k + 1, 3))
    labels = rng.integers(0, 4, k + 1)
    dist, idx = knn_graph(X, k, method="exact")
    gi, gj, gd = graph_mutual_pairs(dist, idx, labels)
    ei, ej, ed = mutual_pairs(X, labels)
    assert _edges(gi, gj) == _edges(ei, ej)
    assert np.allclose(np.sort(gd), np.sort(ed))


def test_parents_restrict_pairs_to_siblings():
    rng = np.random.default_rng(3)
    X = rng.random((400, 2))
    groups = (X[:, 0] > 0.5).astype(int) + 2 * (X[:, 1] > 0.5)
    parents = (X[:, 1] > 0.5).astype(int)
    dist, idx = knn_graph(X, 12)
    i, j, _ = graph_mutual_pairs(dist, idx, groups, parents)
    assert i.size > 0
    assert np.all(parents[i] == parents[j]) and np.all(groups[i] < groups[j])


def test_hnsw_graph_finds_most_exact_neighbours_and_is_deterministic():
    X = np.random.default_rng(4).random((5000, 12))
    d_exact, i_exact = knn_graph(X, 10, method="exact")
    d1, i1 = knn_graph(X, 10, method="hnsw")
    d2, i2 = knn_graph(X, 10, method="hnsw")
    assert np.array_equal(i1, i2) and np.array_equal(d1, d2)
    assert not np.any(i1 == np.arange(5000)[:, None])  # self is never a neighbour
    recall = np.mean([len(set(a) & set(b)) / 10 for a, b in zip(i1, i_exact)])
    assert recall > 0.9
    assert np.all(np.diff(d1, axis=1) >= -1e-6)  # nearest first
    assert np.allclose(d1[:, 0], np.linalg.norm(X - X[i1[:, 0]], axis=1), atol=1e-5)


def test_knn_graph_rejects_unknown_method():
    with pytest.raises(ValueError, match="method"):
        knn_graph(np.zeros((3, 2)), 1, method="lsh")


def test_hnsw_graph_pairs_match_the_exact_graph_pairs():
    # The approximate graph must give (nearly) the pairs of the exact k-graph at every level
    # of a sub-boundary tree: same clusters, >= 95 % of the pairs, no type with 2+ pairs lost.
    import rapt
    from rapt.testfunctions.hierarchical import HierarchicalND

    h = HierarchicalND(dim=10)
    X = np.random.default_rng(7).random((3000, 10))
    Y = h(X)
    exact = rapt.subboundary_tree(X, Y, h.score_tree, exact_below=0, neighbours="exact")
    fast = rapt.subboundary_tree(X, Y, h.score_tree, exact_below=0, neighbours="hnsw")
    assert np.array_equal(exact.assignment, fast.assignment)
    for lv in range(4):
        ei, ej, ed, _ = exact.pairs(lv)
        fi, fj, fd, _ = fast.pairs(lv)
        e, f = _edges(ei, ej), _edges(fi, fj)
        assert len(e) > 20
        assert len(e & f) >= 0.95 * len(e) and len(e & f) >= 0.95 * len(f), (lv, len(e), len(f), len(e & f))
        a = exact.assignment[lv]
        types, counts = np.unique(np.column_stack([a[ei], a[ej]]), axis=0, return_counts=True)
        found = _edges(a[fi], a[fj])
        assert all((int(s), int(t)) in found for (s, t), c in zip(types, counts) if c >= 2), lv
        assert np.array_equal(fast.neighbours.shape, (3000, 12))


def test_hnsw_pairs_are_deterministic():
    import rapt
    from rapt.testfunctions.hierarchical import HierarchicalND

    h = HierarchicalND(dim=10)
    X = np.random.default_rng(8).random((3000, 10))
    a = rapt.subboundary_tree(X, h(X), h.score_tree, exact_below=0, neighbours="hnsw")
    b = rapt.subboundary_tree(X, h(X), h.score_tree, exact_below=0, neighbours="hnsw")
    for lv in range(4):
        assert all(np.array_equal(u, v) for u, v in zip(a.pairs(lv), b.pairs(lv)))


# -- the graph grown batch by batch (rapt.neighbours) ------------------------------------
def _grown(X, sizes, **kw):
    from rapt.neighbours import GrowingGraph

    g = GrowingGraph(X.shape[1], **kw)
    edges = np.r_[0, np.cumsum(sizes)]
    for a, b in zip(edges[:-1], edges[1:]):
        g.add(X[a:b])
    assert g.n == X.shape[0]
    return g


def test_grown_graph_is_the_exact_knn_graph_while_small():
    X = np.random.default_rng(11).random((1500, 5))
    sizes = [1, 0, 7, 300, 2, 690, 500]  # a lone row, an empty batch, uneven batches
    dist, idx = _grown(X, sizes, k=12).graph()
    d_ref, i_ref = knn_graph(X, 12, method="exact")
    assert dist.dtype == np.float32 and idx.dtype == np.int32 and idx.shape == (1500, 12)
    assert all(set(a) == set(b) for a, b in zip(idx.tolist(), i_ref.tolist()))
    np.testing.assert_allclose(dist, d_ref, rtol=1e-6)
    assert np.all(np.diff(dist, axis=1) >= 0)  # nearest first


def test_grown_graph_pads_short_lists_with_the_row_itself():
    from rapt.neighbours import GrowingGraph

    g = GrowingGraph(2, k=4)
    g.add(np.array([[0.0, 0.0], [1.0, 0.0]]))
    dist, idx = g.graph()
    assert idx.tolist() == [[1, 0, 0, 0], [0, 1, 1, 1]]
    assert np.isinf(dist[:, 1:]).all() and dist[0, 0] == np.float32(1.0)


def test_grown_hnsw_graph_recall_and_determinism():
    """Beyond exact_max the batches are linked through HNSW: most exact neighbours found, the same every time."""
    X = np.random.default_rng(12).random((4000, 18))
    sizes = [400] * 10
    a = _grown(X, sizes, k=12, exact_max=800)
    b = _grown(X, sizes, k=12, exact_max=800)
    (da, ia), (db, ib) = a.graph(), b.graph()
    assert ia.tobytes() == ib.tobytes() and da.tobytes() == db.tobytes()
    _, exact = knn_graph(X, 12, method="exact")
    recall = np.mean([len(set(p) & set(q)) for p, q in zip(ia.tolist(), exact.tolist())]) / 12
    assert recall >= 0.9, recall
    true_d = np.linalg.norm(X[ia] - X[:, None, :], axis=2)
    np.testing.assert_allclose(da, true_d, rtol=1e-5)  # distances are the rows' own


def test_grown_graph_rejects_bad_rows_and_k():
    from rapt.neighbours import GrowingGraph

    with pytest.raises(ValueError, match="neighbour_graph: expected a positive number"):
        GrowingGraph(3, k=0)
    with pytest.raises(ValueError, match="U: expected rows of 3 inputs"):
        GrowingGraph(3).add(np.zeros((4, 2)))
