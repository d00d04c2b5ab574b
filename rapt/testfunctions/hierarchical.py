"""Systems whose outputs form a score tree (section 4.3.2): sub-boundaries of nested scores.

Hierarchical2D is the dissertation's 12-element example; HierarchicalND a mission-like
tree of 66 leaves over many inputs for the benchmarks.  Each exposes ``score_tree``.
"""

from __future__ import annotations

import numpy as np

from rapt.testfunctions.base import SyntheticSystem

__all__ = ["Hierarchical2D", "HierarchicalND"]


class Hierarchical2D(SyntheticSystem):
    """Section 4.3.2's hierarchical system: 2 inputs, 12 binary score elements in 3 levels.

    Leaves (columns 6-11) are regions of the square (half-planes and discs); level 2
    (columns 2-5) combines them (``s1 = l1 ∧ l2``, ``s2 = l3``, ``s3 = l4 ∧ l5``,
    ``s4 = l6``); the root is mission ``s1 ∧ s2`` (column 0) and safety ``s3 ∧ s4``
    (column 1), giving the four modes TF, SS, MS, TS.  :attr:`score_tree` declares the
    nesting.  Boundaries of composite elements have no simple closed form, so distances
    are measured to boundary points extracted from a fine grid (resolution ``1/grid``).
    """

    SCORE_TREE = {
        "name": "root",
        "indices": [0, 1],
        "children": [
            {
                "name": "s1",
                "indices": [2],
                "children": [{"name": "l1", "indices": [6]}, {"name": "l2", "indices": [7]}],
            },
            {"name": "s2", "indices": [3], "children": [{"name": "l3", "indices": [8]}]},
            {
                "name": "s3",
                "indices": [4],
                "children": [{"name": "l4", "indices": [9]}, {"name": "l5", "indices": [10]}],
            },
            {"name": "s4", "indices": [5], "children": [{"name": "l6", "indices": [11]}]},
        ],
    }

    def __init__(self, grid: int = 1024):
        self.dim = 2
        self.n_outputs = 12
        self.output_types = ("categorical",) * 12
        self.n_classes = (2,) * 12
        self.active_dims = ((0, 1),) * 12
        self.name = "hierarchical2d"
        self.grid = int(grid)
        self._trees = None

    @property
    def score_tree(self) -> dict:
        return self.SCORE_TREE

    def _evaluate(self, X):
        x, y = X[:, 0], X[:, 1]
        l1 = x + y < 1.3
        l2 = np.hypot(x - 0.75, y - 0.55) > 0.15
        l3 = y < 0.8
        l4 = np.hypot(x - 0.15, y - 0.45) > 0.2
        l5 = x > 0.1
        l6 = x - y < 0.55
        s1, s2, s3, s4 = l1 & l2, l3, l4 & l5, l6
        cols = [s1 & s2, s3 & s4, s1, s2, s3, s4, l1, l2, l3, l4, l5, l6]
        return np.column_stack(cols).astype(float)

    def _boundary_trees(self):
        if self._trees is None:
            from scipy.spatial import cKDTree

            g = self.grid
            c = (np.arange(g) + 0.5) / g
            xx, yy = np.meshgrid(c, c, indexing="ij")
            V = self._evaluate(np.column_stack([xx.ravel(), yy.ravel()])).reshape(g, g, 12)
            trees = []
            for k in range(12):
                v = V[:, :, k]
                pts = []
                dx = np.argwhere(v[1:, :] != v[:-1, :])
                pts.append(np.column_stack([(dx[:, 0] + 1.0) / g, (dx[:, 1] + 0.5) / g]))
                dy = np.argwhere(v[:, 1:] != v[:, :-1])
                pts.append(np.column_stack([(dy[:, 0] + 0.5) / g, (dy[:, 1] + 1.0) / g]))
                P = np.vstack(pts)
                trees.append(cKDTree(P) if len(P) else None)
            self._trees = trees
        return self._trees

    def _distance(self, X):
        out = np.full((X.shape[0], 12), np.inf)
        for k, tree in enumerate(self._boundary_trees()):
            if tree is not None:
                out[:, k] = tree.query(X, k=1)[0]
        return out


class HierarchicalND(SyntheticSystem):
    """A mission-like score tree over many inputs: 66 leaves in 4 levels (benchmarks).

    Each leaf is a pass/fail region in a 2-D slice of the inputs (fail inside a disc, like
    an obstacle's keep-out): which inputs a leaf reads is drawn with a skewed preference,
    so a few inputs matter to many scores (a UUV's start time) and most to few.  Level 3
    ANDs groups of 3 leaves, level 2 ANDs groups of level-3 nodes, and the root holds
    mission (AND of the first three level-2 nodes) and safety (the other three).
    Columns: 0-1 root, 2-7 level 2, 8-29 level 3, 30-95 leaves.  Leaf boundaries are the
    disc outlines (exact distance in their 2-D slice); composite nodes have no
    closed-form distance and report NaN.
    """

    def __init__(self, dim: int = 18, seed: int = 2018):
        rng = np.random.default_rng(seed)
        self.dim = int(dim)
        n_leaves, n_l3, n_l2 = 66, 22, 6
        self.n_outputs = 2 + n_l2 + n_l3 + n_leaves
        self.output_types = ("categorical",) * self.n_outputs
        self.n_classes = (2,) * self.n_outputs
        self.name = f"hierarchical{self.dim}d"
        pref = 1.0 / np.arange(1, self.dim + 1)
        pref /= pref.sum()
        self.leaf_inputs = np.array([rng.choice(self.dim, size=2, replace=False, p=pref) for _ in range(n_leaves)])
        self.leaf_centres = rng.uniform(0.25, 0.75, size=(n_leaves, 2))
        self.leaf_radii = rng.uniform(0.05, 0.12, size=n_leaves)
        self.l3_groups = [list(range(3 * g, 3 * g + 3)) for g in range(n_l3)]
        sizes = [4, 4, 4, 4, 3, 3]
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self.l2_groups = [list(range(s, s + n)) for s, n in zip(starts, sizes)]
        leaf0, l3_0, l2_0 = 2 + n_l2 + n_l3, 2 + n_l2, 2
        self.active_dims = tuple(
            tuple(range(self.dim)) if k < leaf0 else tuple(int(i) for i in self.leaf_inputs[k - leaf0])
            for k in range(self.n_outputs)
        )

        def children_l3(g: int) -> list[dict]:
            return [{"name": f"leaf{k}", "indices": [leaf0 + k]} for k in self.l3_groups[g]]

        def children_l2(h: int) -> list[dict]:
            return [{"name": f"l3_{g}", "indices": [l3_0 + g], "children": children_l3(g)} for g in self.l2_groups[h]]

        self.score_tree = {
            "name": "root",
            "indices": [0, 1],
            "children": [{"name": f"l2_{h}", "indices": [l2_0 + h], "children": children_l2(h)} for h in range(n_l2)],
        }

    def _evaluate(self, X):
        a, b = self.leaf_inputs[:, 0], self.leaf_inputs[:, 1]
        dx = X[:, a] - self.leaf_centres[:, 0]
        dy = X[:, b] - self.leaf_centres[:, 1]
        leaves = (dx * dx + dy * dy) > self.leaf_radii**2  # pass outside the disc
        l3 = np.column_stack([leaves[:, g].all(axis=1) for g in self.l3_groups])
        l2 = np.column_stack([l3[:, g].all(axis=1) for g in self.l2_groups])
        root = np.column_stack([l2[:, :3].all(axis=1), l2[:, 3:].all(axis=1)])
        return np.hstack([root, l2, l3, leaves]).astype(float)

    def _distance(self, X):
        out = np.full((X.shape[0], self.n_outputs), np.nan)
        a, b = self.leaf_inputs[:, 0], self.leaf_inputs[:, 1]
        r = np.hypot(X[:, a] - self.leaf_centres[:, 0], X[:, b] - self.leaf_centres[:, 1])
        out[:, -len(self.leaf_radii) :] = np.abs(r - self.leaf_radii)
        return out
