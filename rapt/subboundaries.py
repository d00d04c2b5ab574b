"""Sub-boundary trees: boundaries of every score element in one pass (Algorithms 3 and 4).

Clustering on all leaf scores at once is slow (the dissertation's took 2 hours at 863K
runs) and mixes unrelated effects.  Instead the samples are split by the root scores
(performance modes), each cluster is split again by the scores of the next level of the
score tree, and so on down; boundary pairs are found between the sub-clusters of each
parent only, so every step works on ever smaller sets.  Any score element's clusters and
boundary can then be reconstructed from the tree without clustering again.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np

from rapt.boundaries import mutual_pairs
from rapt.modes import performance_modes
from rapt.scores import check_output_types, infer_output_types
from rapt.scoretree import ScoreTree

__all__ = ["SubBoundaryNode", "SubBoundaryTree", "Reconstruction", "subboundary_tree"]


@dataclass
class SubBoundaryNode:
    """One parent cluster split by the scores ``K`` of its level.

    ``members`` are sample indices; ``labels[n]`` is the sub-cluster of ``members[n]``;
    ``values[c]`` the representative (mean) scores ``K`` of sub-cluster ``c``.  Pairs join
    samples of different sub-clusters (global indices ``i``, ``j``).
    """

    level: int
    K: tuple[int, ...]
    members: np.ndarray
    labels: np.ndarray
    values: np.ndarray
    i: np.ndarray
    j: np.ndarray
    distance: np.ndarray
    children: list["SubBoundaryNode"] = field(default_factory=list)

    @property
    def n_clusters(self) -> int:
        return int(self.values.shape[0])

    def walk(self):
        yield self
        for c in self.children:
            yield from c.walk()


@dataclass
class Reconstruction:
    """Clusters and boundary of one score element (Algorithm 4).

    ``clusters`` lists the sample-index arrays of the sub-clusters whose value of the
    element is the requested one; ``members`` is their union.  Boundary pairs
    (``i`` inside, ``j`` outside) are the tree's pairs, at the element's level or above,
    that cross from those clusters to samples where the element differs.
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
    """The result of :func:`subboundary_tree`; ``root`` is the mode split."""

    def __init__(self, root: SubBoundaryNode, tree: ScoreTree, X: np.ndarray, Y: np.ndarray,
                 output_types: tuple[str, ...], assignment: np.ndarray):
        self.root = root
        self.score_tree = tree
        self.X = X
        self.Y = Y
        self.output_types = output_types
        #: ``assignment[l, n]``: global sub-cluster id of sample n at level l (unique across parents).
        self.assignment = assignment

    @property
    def levels(self) -> list[tuple[int, ...]]:
        return self.score_tree.levels()

    def nodes(self) -> list[SubBoundaryNode]:
        return list(self.root.walk())

    def n_clusters(self, level: int) -> int:
        return int(np.unique(self.assignment[level]).size)

    def pairs(self, level: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """All sub-boundary pairs (i, j, distance, level), optionally of one level."""
        parts = [(n.i, n.j, n.distance, np.full(n.i.size, n.level)) for n in self.nodes()
                 if level is None or n.level == level]
        if not parts:
            e = np.empty(0, dtype=np.int64)
            return e, e, np.empty(0), e
        return tuple(np.concatenate(p) for p in zip(*parts))  # type: ignore[return-value]

    def reconstruct(self, score_index: int, value: float) -> Reconstruction:
        """Clusters and boundary pairs of score element ``score_index`` at ``value``."""
        levels = self.levels
        owning = [lv for lv, cols in enumerate(levels) if score_index in cols]
        if not owning:
            raise ValueError(
                f"score_index: column {score_index} is not in the score tree (columns: {sorted(c for l in levels for c in l)})"
            )
        lv = owning[0]
        col = levels[lv].index(score_index)
        clusters: list[np.ndarray] = []
        for node in self.nodes():
            if node.level != lv or node.n_clusters == 0:
                continue
            vals = node.values[:, col]
            if self._is_discrete(score_index):
                chosen = np.flatnonzero(vals == value)  # a discrete cluster has one exact value
            else:
                gap = np.abs(vals - value)  # Algorithm 4: the cluster nearest in score
                chosen = np.flatnonzero(gap == gap.min())
            for c in chosen:
                clusters.append(node.members[node.labels == c])
        members = np.sort(np.concatenate(clusters)) if clusters else np.empty(0, dtype=np.int64)
        inside = np.zeros(self.X.shape[0], dtype=bool)
        inside[members] = True
        # Samples whose own cluster at this level does not have the value are "outside";
        # pairs from this level and every level above can cross the element's boundary.
        i, j, d, l = self.pairs()
        sel = (l <= lv) & (inside[i] != inside[j])
        i, j, d, l = i[sel], j[sel], d[sel], l[sel]
        swap = ~inside[i]
        i, j = np.where(swap, j, i), np.where(swap, i, j)
        order = np.argsort(d, kind="stable")
        return Reconstruction(score_index, float(value), clusters, members, i[order], j[order], d[order], l[order])

    def _is_discrete(self, score_index: int) -> bool:
        return self.output_types[score_index] != "continuous"


def subboundary_tree(X: np.ndarray, Y: np.ndarray, tree: ScoreTree | Mapping[str, Any], *,
                     output_types: Sequence[str] | None = None, bandwidth: float = 0.2,
                     weights: np.ndarray | None = None) -> SubBoundaryTree:
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
        Per-input scale for the nearest-neighbour searches (sensitivity scaling).
    """
    X = np.asarray(X, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if X.ndim != 2 or X.shape[0] == 0:
        raise ValueError(f"X: expected a non-empty (N, d) array of states, got shape {X.shape}")
    if Y.ndim != 2 or Y.shape[0] != X.shape[0]:
        raise ValueError(f"Y: expected {X.shape[0]} score rows (one per state), got shape {Y.shape}")
    if not np.all(np.isfinite(Y)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(Y), axis=1))[0])
        raise ValueError(f"Y: scores must be finite; row {bad} has NaN or inf (drop failed runs first)")
    try:
        tree = ScoreTree.from_mapping(tree)
    except TypeError:
        raise ValueError("tree: expected a ScoreTree or a mapping with 'indices' and 'children'") from None
    tree.validate(Y.shape[1])
    types = infer_output_types(Y) if output_types is None else check_output_types(output_types, Y.shape[1])
    Xs = X if weights is None else X * _check_weights(weights, X.shape[1])
    levels = tree.levels()
    assignment = np.zeros((len(levels), X.shape[0]), dtype=np.int64)
    counter = [0]

    def build(members: np.ndarray, level: int) -> SubBoundaryNode:
        K = levels[level]
        cols = list(K)
        sub = performance_modes(Y[np.ix_(members, cols)], [types[c] for c in cols], bandwidth=bandwidth)
        n_sub = int(sub.max()) + 1
        values = np.vstack([Y[np.ix_(members[sub == c], cols)].mean(axis=0) for c in range(n_sub)])
        assignment[level, members] = counter[0] + sub
        counter[0] += n_sub
        if n_sub > 1:
            li, lj, d = mutual_pairs(Xs[members], sub)
            gi, gj = members[li], members[lj]
        else:
            gi = gj = np.empty(0, dtype=np.int64)
            d = np.empty(0)
        order = np.lexsort((gj, gi, d))
        node = SubBoundaryNode(level, tuple(K), members, sub, values, gi[order], gj[order], d[order])
        if level + 1 < len(levels):
            for c in range(n_sub):
                child_members = members[sub == c]
                if child_members.size >= 1:
                    node.children.append(build(child_members, level + 1))
        return node

    root = build(np.arange(X.shape[0]), 0)
    return SubBoundaryTree(root, tree, X, Y, tuple(types), assignment)


def _check_weights(weights: np.ndarray, d: int) -> np.ndarray:
    w = np.asarray(weights, dtype=float)
    if w.shape != (d,) or np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError(f"weights: expected {d} non-negative finite scale factors")
    return w
