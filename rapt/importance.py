"""Tree-based variable importance: which inputs move which score (section 3.4.3).

S-NDV scales each input by its importance for each output so that non-contributing
inputs look identical to the distance metric.  A CART tree's impurity-decrease importance
(Breiman) is cheap, O(m n log n), and is fitted on a bounded random subsample so that the
cost per batch stays flat as a study grows to millions of samples.
"""

from __future__ import annotations

import numpy as np
from sklearn.tree import DecisionTreeClassifier, DecisionTreeRegressor

from rapt.errors import InputError

__all__ = ["tree_importance", "importance_weights", "output_importance", "boundary_type_importance"]


def tree_importance(
    X: np.ndarray,
    y: np.ndarray,
    kind: str,
    *,
    max_samples: int = 20000,
    random_state: int | np.random.Generator = 0,
    min_samples_leaf: int = 2,
    max_depth: int | None = 16,
) -> np.ndarray:
    """Impurity-decrease importance of each column of ``X`` for score ``y``.

    ``kind`` is ``"categorical"``/``"binary"`` (classification tree, Gini) or
    ``"continuous"`` (regression tree, squared error).  Returns a non-negative vector that
    sums to 1, or all zeros when ``y`` is constant (no input explains anything yet).
    """
    X = np.asarray(X, dtype=float)
    y = np.asarray(y)
    if X.ndim != 2 or X.shape[0] != y.shape[0]:
        raise InputError(f"X, y: expected X (n, d) and y (n,), got {X.shape} and {y.shape}")
    if kind not in ("categorical", "binary", "continuous"):
        raise InputError(f"kind: unknown score kind {kind!r}; allowed: categorical, binary, continuous")
    rng = np.random.default_rng(random_state)
    if X.shape[0] > max_samples:
        rows = np.sort(rng.choice(X.shape[0], size=max_samples, replace=False))
        X, y = X[rows], y[rows]
    if X.shape[0] < 2 or np.all(y == y[0]):
        return np.zeros(X.shape[1])
    seed = int(rng.integers(2**31 - 1))
    if kind == "continuous":
        model = DecisionTreeRegressor(min_samples_leaf=min_samples_leaf, max_depth=max_depth, random_state=seed)
    else:
        model = DecisionTreeClassifier(min_samples_leaf=min_samples_leaf, max_depth=max_depth, random_state=seed)
    model.fit(X, y)
    imp = np.asarray(model.feature_importances_, dtype=float)
    total = imp.sum()
    return imp / total if total > 0 else np.zeros(X.shape[1])


def importance_weights(importance: np.ndarray) -> np.ndarray:
    """Per-dimension scale factors from an importance vector: the most important input keeps
    its unit range; an all-zero vector (nothing learned yet) gives uniform weights."""
    importance = np.asarray(importance, dtype=float)
    top = importance.max() if importance.size else 0.0
    if top <= 0:
        return np.ones_like(importance)
    return importance / top


def output_importance(
    X: np.ndarray, Y: np.ndarray, output_types, *, max_samples: int = 20000, random_state: int = 0
) -> np.ndarray:
    """Tree importance of every input for every score column: an (m, d) array, rows sum to 1 or 0."""
    X = np.asarray(X, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    types = tuple(output_types)
    if len(types) != Y.shape[1]:
        raise InputError(f"output_types: got {len(types)} types for {Y.shape[1]} score columns")
    return np.vstack(
        [
            tree_importance(
                X,
                Y[:, k],
                "continuous" if t == "continuous" else "categorical",
                max_samples=max_samples,
                random_state=random_state + k,
            )
            for k, t in enumerate(types)
        ]
    )


def boundary_type_importance(
    X: np.ndarray, labels: np.ndarray, types, *, max_samples: int = 20000, random_state: int = 0
) -> dict[tuple[int, int], np.ndarray]:
    """Per boundary type ``(a, b)``: which inputs separate mode ``a`` from mode ``b``.

    A classification tree is fitted on the samples of the two modes only, so the answer is
    specific to that transition (e.g. start time for a fuel boundary, an obstacle's
    position for a collision boundary).
    """
    X = np.asarray(X, dtype=float)
    labels = np.asarray(labels)
    out = {}
    for n, t in enumerate(types):
        a, b = int(t[0]), int(t[1])
        rows = np.flatnonzero((labels == a) | (labels == b))
        out[(a, b)] = tree_importance(
            X[rows], labels[rows], "categorical", max_samples=max_samples, random_state=random_state + n
        )
    return out
