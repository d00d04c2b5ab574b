"""Small picklable systems under test shared by the test modules."""

import numpy as np


def disk(X):
    """1 inside a disk of radius 0.3 around (0.5, 0.5), else 0 — boundary is a circle."""
    X = np.asarray(X, dtype=float)
    return (np.hypot(X[:, 0] - 0.5, X[:, 1] - 0.5) < 0.3).astype(float)[:, None]


def disk_distance(X):
    return np.abs(np.hypot(X[:, 0] - 0.5, X[:, 1] - 0.5) - 0.3)


def two_outputs(X):
    """Output 0 depends on x0 only (step at 0.4), output 1 on x2 only (continuous ramp with a cliff)."""
    X = np.asarray(X, dtype=float)
    y0 = (X[:, 0] > 0.4).astype(float)
    y1 = 0.2 * X[:, 2] + (X[:, 2] > 0.7)
    return np.column_stack([y0, y1])


def flaky(X):
    """Like disk(), but rows with x0 < 0.1 are invalid scenarios (NaN) and a batch containing
    a point with x1 > 0.97 crashes."""
    X = np.asarray(X, dtype=float)
    if np.any(X[:, 1] > 0.97):
        raise RuntimeError("simulator crashed")
    Y = disk(X)
    Y[X[:, 0] < 0.1] = np.nan
    return Y


def projecting(X):
    """Evaluates the state snapped to a 0.05 grid and reports the state it used."""
    X = np.round(np.asarray(X, dtype=float) / 0.05) * 0.05
    return X, disk(X)


def first_of_two_outputs(X):
    """Column 0 of two_outputs alone."""
    return two_outputs(X)[:, :1]
