"""Input checks shared by the analysis functions, so every one names the argument alike."""

from __future__ import annotations

import numpy as np

from rapt.errors import InputError

__all__ = ["check_states", "check_scores"]


def check_states(X) -> np.ndarray:
    """A non-empty, finite (N, d) float array of states."""
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[0] == 0:
        raise InputError(f"X: expected a non-empty (N, d) array of states, got shape {X.shape}")
    if not np.all(np.isfinite(X)):
        raise InputError("X: states must be finite")
    return X


def check_scores(Y, n: int | None = None) -> np.ndarray:
    """A finite (N, m) float array of scores (a 1-D array is one column), N = ``n`` if given."""
    Y = np.asarray(Y, dtype=float)
    if Y.ndim == 1:
        Y = Y[:, None]
    if Y.ndim != 2:
        raise InputError(f"Y: expected an (N, m) array of scores, got shape {Y.shape}")
    if n is not None and Y.shape[0] != n:
        raise InputError(f"Y: expected {n} score rows (one per state), got {Y.shape[0]}")
    if Y.shape[0] == 0:
        raise InputError("Y: no samples; at least one scored sample is needed")
    if Y.shape[1] == 0:
        raise InputError("Y: no score columns")
    if not np.all(np.isfinite(Y)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(Y), axis=1))[0])
        raise InputError(f"Y: scores must be finite; row {bad} has NaN or inf (drop failed runs first)")
    return Y
