"""Sub-boundary trees: boundaries of every score element in one pass (Algorithms 3 and 4).

Clustering on all leaf scores at once is slow (the dissertation's took 2 hours at 863K
runs) and mixes unrelated effects.  Instead the samples are split by the root scores
(performance modes), each cluster is split again by the scores of the next level of the
score tree, and so on down; boundary pairs are found between the sub-clusters of each
parent only.  Any score element's clusters and boundary can then be reconstructed from
the tree without clustering again.

Implementation: a level's sub-clusters are the distinct (parent cluster, level scores)
combinations — one vectorised ``unique`` per level for discrete scores, mean shift per
parent for continuous ones.  Pairs come from one k-nearest-neighbour graph of the
samples, built once and filtered per level (:func:`rapt.boundaries.graph_mutual_pairs`),
so the cost does not grow with the number of sub-clusters, which runs into thousands for
a 66-leaf tree.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rapt.boundaries import exact_order, graph_mutual_pairs, knn_graph
from rapt.errors import InputError
from rapt.modes import mean_shift_normalised
from rapt.scores import check_output_types, infer_output_types, row_codes
from rapt.scoretree import ScoreTree
from rapt.validation import check_scores, check_states

__all__ = ["SubBoundaryTree", "Reconstruction", "subboundary_tree"]


@dataclass
class Reconstruction:
    """Clusters and boundary of one score element (Algorithm 4).

    ``clusters`` lists the sample-index arrays of the sub-clusters whose value of the
    element is the requested one; ``members`` is their union.  Boundary pairs
    (``i`` inside, ``j`` outside) are the tree's pairs, at the element's level or above,
    that cross from those clusters to samples outside them.
    """

    score_index: int
    value: float
    clusters: list[np.ndarray]
    members: np.ndarray
    i: np.ndarray
    j: np.ndarray
    distance: np.ndarray
    level: np.ndarray

    def __len__(self) -> int:
        return int(self.i.shape[0])


class SubBoundaryTree:
    """The result of :func:`subboundary_tree`.

    ``assignment[l, n]`` is sample n's sub-cluster at level l (ids unique across parents);
    ``values[l][c]`` the mean scores of level l's columns in cluster c; ``parent[l][c]``
    the level l-1 cluster that c splits (-1 at the root).
    """

    def __init__(
        self,
        tree: ScoreTree,
        X: np.ndarray,
        Y: np.ndarray,
        output_types: tuple[str, ...],
        assignment: np.ndarray,
        values: list[np.ndarray],
        parent: list[np.ndarray],
        pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        k: int,
    ):
        self.score_tree = tree
        self.levels = tree.levels()
        self.X = X
        self.Y = Y
        self.output_types = output_types
        self.assignment = assignment
        self.values = values
        self.parent = parent
        self._pairs = pairs
        self.k = k
        #: Each sample's graph neighbours (N, k), nearest first; set by :func:`subboundary_tree`.
        self.neighbours: np.ndarray | None = None
        #: Seconds spent splitting the levels, building the neighbour graph and pairing.
        self.timings: dict[str, float] = {}

    def n_clusters(self, level: int) -> int:
        return int(self.values[level].shape[0])

    def children(self, level: int, cluster: int) -> np.ndarray:
        """Sub-clusters at ``level + 1`` of cluster ``cluster`` at ``level``."""
        return np.flatnonzero(self.parent[level + 1] == cluster)

    def members(self, level: int, cluster: int) -> np.ndarray:
        return np.flatnonzero(self.assignment[level] == cluster)

    def pairs(self, level: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Sub-boundary pairs (i, j, distance, level) sorted by distance, optionally of one level."""
        chosen = range(len(self.levels)) if level is None else [level]
        parts = [(*self._pairs[lv], np.full(self._pairs[lv][0].size, lv, dtype=np.int64)) for lv in chosen]
        i, j, d, lv = (np.concatenate(p) for p in zip(*parts))
        order = np.lexsort((j, i, d))
        return i[order], j[order], d[order], lv[order]

    def reconstruct(self, score_index: int, value: float) -> Reconstruction:
        """Clusters and boundary pairs of score element ``score_index`` at ``value``."""
        owning = [lv for lv, cols in enumerate(self.levels) if score_index in cols]
        if not owning:
            cols = sorted(c for level in self.levels for c in level)
            raise InputError(f"score_index: column {score_index} is not in the score tree (columns: {cols})")
        lv = owning[0]
        vals = self.values[lv][:, self.levels[lv].index(score_index)]
        if self.output_types[score_index] != "continuous":
            chosen = np.flatnonzero(vals == value)  # a discrete cluster has one exact value
        else:  # Algorithm 4: within each parent, the cluster nearest in score
            gap = np.abs(vals - value)
            par = self.parent[lv]
            best = np.full(par.max() + 2, np.inf)
            np.minimum.at(best, par + 1, gap)
            chosen = np.flatnonzero(gap == best[par + 1])
        inside = np.isin(self.assignment[lv], chosen)
        clusters = [self.members(lv, int(c)) for c in chosen]
        members = np.flatnonzero(inside)
        i, j, d, level = self.pairs()
        sel = (level <= lv) & (inside[i] != inside[j])
        i, j, d, level = i[sel], j[sel], d[sel], level[sel]
        swap = ~inside[i]
        i, j = np.where(swap, j, i), np.where(swap, i, j)
        return Reconstruction(score_index, float(value), clusters, members, i, j, d, level)


def subboundary_tree(
    X: np.ndarray,
    Y: np.ndarray,
    tree: ScoreTree | Mapping[str, Any],
    *,
    output_types: Sequence[str] | None = None,
    bandwidth: float = 0.2,
    weights: np.ndarray | None = None,
    k: int = 12,
    exact_below: int = 2000,
    neighbours: str = "auto",
    graph: tuple[np.ndarray, np.ndarray] | None = None,
) -> SubBoundaryTree:
    """Algorithm 3: split by the score tree level by level and pair sub-clusters within parents.

    Parameters
    ----------
    X, Y:
        (N, d) states (normally unit cube) and (N, m) scores.
    tree:
        A :class:`~rapt.scoretree.ScoreTree` or the same as nested mappings
        ``{"indices": [...], "children": [...]}``.
    output_types:
        Per score column; inferred when omitted.  Continuous columns are clustered with
        mean shift (bandwidth ``λ_P`` on normalised scores) inside each parent cluster.
    weights:
        Per-input scale for the neighbour searches (sensitivity scaling, section 3.5.3).
    k, exact_below:
        Pairs are mutual nearest neighbours within each sample's ``k`` nearest samples;
        below ``exact_below`` samples the graph is complete, which is exactly
        Algorithm 3's two nearest-neighbour searches per pair of sub-clusters.
    neighbours:
        How the k-graph is built: ``"exact"``, ``"hnsw"`` (approximate, for 10^5+ samples
        in many dimensions) or ``"auto"`` (see :func:`rapt.boundaries.knn_graph`).
    graph:
        A ready k-nearest-neighbour graph of ``X``'s rows, ``(dist, idx)`` both (N, k'),
        nearest first (e.g. ``Study.neighbours``, grown during the search): used instead
        of building one, which is most of the cost for large studies.  Only its first
        ``k`` columns are used; each row's neighbours are re-ordered by their exact
        distance in ``X`` and the pairs' distances measured there, so a graph stored in
        float32 gives the same pairs as the exact graph it holds.  Below ``exact_below``
        samples it is ignored and the complete graph built as without it, so small studies
        keep their results.  It cannot be combined with ``weights``, which change the
        distances the graph was built on.
    """
    started = time.perf_counter()
    X = check_states(X)
    Y = check_scores(Y, X.shape[0])
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise InputError(f"k: expected a positive number of neighbours, got {k!r}")
    if neighbours not in ("auto", "exact", "hnsw"):
        raise InputError(f"neighbours: expected 'auto', 'exact' or 'hnsw', got {neighbours!r}")
    if not isinstance(tree, (ScoreTree, Mapping)):
        raise InputError("tree: expected a ScoreTree or a mapping with 'indices' and 'children'")
    tree = ScoreTree.from_mapping(tree)
    tree.validate(Y.shape[1])
    columns = np.ascontiguousarray(Y.T)  # (m, N): a column of the row-major (N, m) matrix is strided
    types = infer_output_types(columns.T) if output_types is None else check_output_types(output_types, Y.shape[1])
    Xs = X if weights is None else X * _check_weights(weights, X.shape[1])
    n = X.shape[0]
    if graph is not None:
        graph = _check_graph(graph, n, weights)
    levels = tree.levels()

    assignment = np.empty((len(levels), n), dtype=np.int64)
    values: list[np.ndarray] = []
    parents: list[np.ndarray] = []
    previous = np.zeros(n, dtype=np.int64)
    for lv, K in enumerate(levels):
        cols = list(K)
        sub, n_sub = _split(previous, columns[cols], [types[c] for c in cols], bandwidth)
        keys, inverse = np.unique(previous * n_sub + sub, return_inverse=True)  # (parent, sub) in order
        inverse = inverse.reshape(-1)
        assignment[lv] = inverse
        counts = np.bincount(inverse, minlength=keys.size).astype(float)
        values.append(
            np.column_stack([np.bincount(inverse, weights=columns[c], minlength=keys.size) / counts for c in cols])
        )
        parents.append(keys // n_sub if lv else np.full(keys.size, -1, dtype=np.int64))
        previous = inverse

    split_done = time.perf_counter()
    if graph is None or n <= exact_below:
        dist, idx = knn_graph(Xs, n - 1 if n <= exact_below else int(k), method=neighbours)
    else:
        dist, idx = exact_order(Xs, graph[1][:, : int(k)])
    graph_done = time.perf_counter()
    pairs = []
    for lv in range(len(levels)):
        parent = assignment[lv - 1] if lv else None
        pairs.append(graph_mutual_pairs(dist, idx, assignment[lv], parent))
    result = SubBoundaryTree(tree, X, Y, tuple(types), assignment, values, parents, pairs, idx.shape[1])
    result.neighbours = idx  # the (N, k) neighbour graph the pairs came from (nearest first)
    result.timings = {
        "split": split_done - started,
        "graph": graph_done - split_done,
        "pairs": time.perf_counter() - graph_done,
    }
    return result


def _split(parent: np.ndarray, columns: np.ndarray, types: list[str], bandwidth: float) -> tuple[np.ndarray, int]:
    """Sub-cluster code of each sample within its parent from this level's score columns: (codes, count).

    Continuous columns are normalised once over all samples, then mean-shifted inside each
    parent, so ``bandwidth`` (λ_P) means the same score difference in every parent.
    """
    parts = [col for col, t in zip(columns, types) if t != "continuous"]
    continuous = np.array([col for col, t in zip(columns, types) if t == "continuous"])
    if continuous.size:
        lo, hi = continuous.min(axis=1, keepdims=True), continuous.max(axis=1, keepdims=True)
        Z = ((continuous - lo) / np.where(hi > lo, hi - lo, 1.0)).T
        order = np.argsort(parent, kind="stable")
        bounds = np.flatnonzero(np.diff(parent[order])) + 1
        lab = np.zeros(parent.shape[0])
        for rows in np.split(order, bounds):
            lab[rows] = mean_shift_normalised(Z[rows], bandwidth)
        parts.append(lab)
    return row_codes(parts)


def _check_graph(graph: Any, n: int, weights: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """A given neighbour graph checked against the samples: (dist, idx), (n, k) with indices in range."""
    if weights is not None:
        raise InputError("graph: a ready neighbour graph cannot be combined with weights; pass one or the other")
    if not (isinstance(graph, (tuple, list)) and len(graph) == 2):
        raise InputError("graph: expected (dist, idx), two (N, k) arrays such as Study.neighbours")
    dist, idx = np.asarray(graph[0]), np.asarray(graph[1])
    if dist.ndim != 2 or dist.shape != idx.shape or dist.shape[0] != n or dist.shape[1] < 1:
        raise InputError(
            f"graph: expected (dist, idx) of shape ({n}, k) each, one row per sample; got {dist.shape} and {idx.shape}"
        )
    if not np.issubdtype(idx.dtype, np.integer) or (idx.size and (idx.min() < 0 or idx.max() >= n)):
        raise InputError(f"graph: idx must hold integer sample indices in [0, {n})")
    return dist, idx


def _check_weights(weights: np.ndarray, d: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float)
    if w.shape != (d,) or np.any(w < 0) or not np.all(np.isfinite(w)):
        raise InputError(f"weights: expected {d} non-negative finite scale factors")
    return w
