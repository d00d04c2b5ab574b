"""Score trees and sub-boundary trees (section 4.2): hand-built trees, a hierarchical system's known boundaries, errors."""

import numpy as np
import pytest

import rapt
from rapt.metrics import subboundary_recovery
from rapt.scoretree import ScoreTree
from rapt.testfunctions.hierarchical import Hierarchical2D


def test_score_tree_from_nested_mappings():
    tree = ScoreTree.from_mapping(Hierarchical2D.SCORE_TREE)
    assert tree.levels() == [(0, 1), (2, 3, 4, 5), (6, 7, 8, 9, 10, 11)]
    assert [leaf.name for leaf in tree.leaves()] == ["l1", "l2", "l3", "l4", "l5", "l6"]
    assert ScoreTree.from_mapping(tree.to_mapping()) == tree
    assert tree.depth == 3


@pytest.mark.parametrize(
    "spec, match",
    [
        ({"indices": [0], "children": [{"indices": [7]}]}, "names score column 7, but Y has 3 columns"),
        ({"indices": [0], "children": [{"indices": [0]}]}, "column 0 appears in two nodes"),
        ({"indices": []}, "has no score indices"),
        ({"indices": [0], "kids": []}, r"unknown field\(s\) \['kids'\]"),
        ({"children": []}, "missing 'indices'"),
        ({"indices": [0], "children": [{"indices": ["a"]}]}, r"tree.children\[0\].indices: 'a' is not a column number"),
    ],
)
def test_bad_trees_name_the_field(spec, match):
    with pytest.raises(ValueError, match=match):
        rapt.subboundary_tree(np.zeros((4, 2)), np.zeros((4, 3)), spec)


def test_hand_built_tree_and_reconstruction():
    # 1-D states; root score r splits at x=0.5; its child c splits the r=0 half at x=0.25.
    X = np.array([[0.0], [0.1], [0.2], [0.3], [0.4], [0.6], [0.7], [0.9]])
    r = (X[:, 0] > 0.5).astype(float)
    c = (X[:, 0] > 0.25).astype(float)
    Y = np.column_stack([r, c])
    T = rapt.subboundary_tree(X, Y, {"indices": [0], "children": [{"indices": [1]}]})
    i, j, d, lv = T.pairs(0)
    assert list(zip(i, j)) == [(4, 5)] and d == pytest.approx([0.2])
    i, j, d, lv = T.pairs(1)
    assert list(zip(i, j)) == [(2, 3)] and lv.tolist() == [1]  # only inside the r=0 parent
    assert T.n_clusters(0) == 2 and T.n_clusters(1) == 3
    rec = T.reconstruct(1, 1.0)  # where c = 1: x in {0.3, 0.4} (r=0) and {0.6, 0.7, 0.9} (r=1)
    assert sorted(rec.members.tolist()) == [3, 4, 5, 6, 7]
    assert sorted(zip(rec.i.tolist(), rec.j.tolist())) == [(3, 2)]
    rec0 = T.reconstruct(0, 0.0)
    assert rec0.members.tolist() == [0, 1, 2, 3, 4] and list(zip(rec0.i, rec0.j)) == [(4, 5)]
    with pytest.raises(ValueError, match="column 5 is not in the score tree"):
        T.reconstruct(5, 1.0)


def test_single_mode_gives_no_boundaries_but_a_tree():
    X = np.random.default_rng(0).random((30, 2))
    Y = np.column_stack([np.ones(30), (X[:, 0] > 0.5)])
    T = rapt.subboundary_tree(X, Y, {"indices": [0], "children": [{"indices": [1]}]})
    assert T.pairs(0)[0].size == 0 and T.pairs(1)[0].size > 0


def test_hierarchical_system_sub_boundaries_match_ground_truth():
    h = Hierarchical2D()
    study = rapt.search(h, [(0, 1)] * 2, 4000, method="s-ndv", seed=0, output_types=("categorical",) * 12)
    T = rapt.subboundary_tree(study.X, study.Y, h.score_tree)
    assert [T.n_clusters(lv) for lv in range(3)] == [4, 8, 12]
    report = subboundary_recovery(h, T, grid=256, tol=0.05)
    for row in report:
        assert row["recovered_fraction"] == 1.0, row
        assert row["on_boundary_fraction"] > 0.85, row
    # Reconstructing a leaf gives clusters where the leaf has that value and pairs on its outline.
    rec = T.reconstruct(9, 0.0)  # l4 = 0: inside the disc at (0.15, 0.45)
    assert np.all(study.Y[rec.members, 9] == 0.0)
    assert np.all(study.Y[rec.j, 9] == 1.0)
    near = h.boundary_distance(study.X)[:, 9]
    assert np.mean(near[rec.i] < 0.03) > 0.9


def test_subboundary_errors():
    with pytest.raises(ValueError, match="Y: expected 3 score rows"):
        rapt.subboundary_tree(np.zeros((3, 2)), np.zeros((2, 1)), {"indices": [0]})
    with pytest.raises(ValueError, match="row 0 has NaN"):
        rapt.subboundary_tree(np.zeros((1, 2)), np.array([[np.nan]]), {"indices": [0]})
    with pytest.raises(ValueError, match="X: expected a non-empty"):
        rapt.subboundary_tree(np.zeros((0, 2)), np.zeros((0, 1)), {"indices": [0]})
    with pytest.raises(ValueError, match="tree: expected a ScoreTree or a mapping"):
        rapt.subboundary_tree(np.zeros((2, 2)), np.zeros((2, 1)), [0])


def test_knn_graph_pairs_agree_with_exact_pairs_on_short_boundaries():
    h = Hierarchical2D()
    X = np.random.default_rng(5).random((3000, 2))
    Y = h(X)
    exact = rapt.subboundary_tree(X, Y, h.score_tree, exact_below=10**6)
    graph = rapt.subboundary_tree(X, Y, h.score_tree, k=12, exact_below=0)
    for lv in range(3):
        ei, ej, ed, _ = exact.pairs(lv)
        gi, gj, gd, _ = graph.pairs(lv)
        g = set(zip(gi.tolist(), gj.tolist()))
        short = ed <= np.quantile(ed, 0.5)
        # every short exact pair is found by the graph, and the graph invents none
        assert all((a, b) in g for a, b in zip(ei[short].tolist(), ej[short].tolist()))
        assert g <= set(zip(ei.tolist(), ej.tolist()))
    assert np.array_equal(exact.assignment, graph.assignment)


def test_children_and_members_follow_the_hierarchy():
    h = Hierarchical2D()
    X = np.random.default_rng(1).random((2000, 2))
    T = rapt.subboundary_tree(X, h(X), h.score_tree)
    for c in range(T.n_clusters(0)):
        kids = T.children(0, c)
        assert kids.size >= 1
        assert sorted(np.concatenate([T.members(1, kc) for kc in kids]).tolist()) == T.members(0, c).tolist()


def _hierarchical_sample(n, seed=6):
    h = Hierarchical2D()
    X = np.random.default_rng(seed).random((n, 2))
    return h, X, h(X)


def test_a_given_graph_gives_the_pairs_of_the_graph_it_replaces():
    from rapt.neighbours import GrowingGraph

    h, X, Y = _hierarchical_sample(2500)
    grown = GrowingGraph(2, k=12)
    for s in range(0, 2500, 300):
        grown.add(X[s : s + 300])
    built = rapt.subboundary_tree(X, Y, h.score_tree, exact_below=100)
    given = rapt.subboundary_tree(X, Y, h.score_tree, exact_below=100, graph=grown.graph())
    (bi, bj, bd, bl), (gi, gj, gd, gl) = built.pairs(), given.pairs()
    assert bi.size > 100
    assert np.array_equal(bi, gi) and np.array_equal(bj, gj) and np.array_equal(bl, gl)
    np.testing.assert_allclose(gd, bd, rtol=1e-12)  # measured in X, not the graph's float32
    assert given.timings["graph"] < built.timings["graph"]


def test_a_given_graph_is_ignored_below_exact_below():
    """Small studies keep the complete graph, so their pairs do not change with the option."""
    h, X, Y = _hierarchical_sample(400)
    nonsense = (np.ones((400, 3)), np.zeros((400, 3), dtype=np.int32))
    plain = rapt.subboundary_tree(X, Y, h.score_tree)
    given = rapt.subboundary_tree(X, Y, h.score_tree, graph=nonsense)
    assert all(np.array_equal(a, b) for a, b in zip(plain.pairs(), given.pairs()))
    with_graph = rapt.subboundary_tree(X, Y, h.score_tree, graph=nonsense, exact_below=0)
    assert with_graph.pairs()[0].size == 0  # above exact_below it is what the pairs come from


@pytest.mark.parametrize(
    ("graph", "weights", "match"),
    [
        ((np.zeros((9, 3)), np.zeros((9, 3), dtype=int)), None, r"graph: expected \(dist, idx\) of shape \(10, k\)"),
        ((np.zeros((10, 3)), np.zeros((10, 2), dtype=int)), None, r"graph: expected \(dist, idx\) of shape"),
        (np.zeros((10, 3)), None, r"graph: expected \(dist, idx\), two"),
        ((np.zeros((10, 3)), np.full((10, 3), 10)), None, r"graph: idx must hold integer sample indices in \[0, 10\)"),
        ((np.zeros((10, 3)), np.zeros((10, 3), dtype=int)), np.ones(2), "graph: a ready neighbour graph cannot"),
    ],
)
def test_bad_graph_is_a_one_line_input_error(graph, weights, match):
    h, X, Y = _hierarchical_sample(10)
    with pytest.raises(rapt.InputError, match=match) as err:
        rapt.subboundary_tree(X, Y, h.score_tree, graph=graph, weights=weights)
    assert "\n" not in str(err.value)
