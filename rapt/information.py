"""Information metrics: how much a proposed query would tell us about a performance boundary.

Plain functions in the style of python-adaptive's loss functions, so samplers stay small
and the metrics can be tested on hand-computed cases:

* :func:`unalikeability` — eq. 3.6/3.7, the spread of categorical labels among neighbours
  (1 when every pair differs, 0 when all agree).
* :func:`nndv_information` — eq. 3.5, ``(σ_K + floor)^g · d_K^v`` from the k nearest
  evaluated samples: neighbour variance (high on a boundary) times mean neighbour distance
  (high where we have not sampled).  The small ``floor`` keeps the density term alive where
  every neighbour agrees, so flat regions are still explored in order of emptiness instead
  of all tying at zero.
* :func:`gpr_information` — eq. 3.4, ``|∇μ|^g · σ^v`` from a Gaussian process.
"""

from __future__ import annotations

import numpy as np

from rapt.errors import InputError

__all__ = ["unalikeability", "neighbour_variance", "nndv_information", "gpr_information"]


def unalikeability(labels: np.ndarray, n_classes: int | None = None) -> np.ndarray:
    """Unalikeability of each row of integer ``labels`` (shape (p, k), codes ``0..C-1``).

    ``u = Σ_{i≠j} [x_i ≠ x_j] / (k² − k) = 1 − Σ_c n_c (n_c − 1) / (k (k − 1))``.
    """
    labels = np.asarray(labels)
    if labels.ndim != 2:
        raise InputError(f"labels: expected a 2-D array (queries, neighbours), got shape {labels.shape}")
    p, k = labels.shape
    if k < 2:
        raise InputError("labels: unalikeability needs at least 2 neighbours per query")
    if n_classes is None:
        n_classes = int(labels.max()) + 1 if labels.size else 1
    flat = (np.arange(p, dtype=np.int64)[:, None] * n_classes + labels.astype(np.int64)).ravel()
    counts = np.bincount(flat, minlength=p * n_classes).reshape(p, n_classes).astype(float)
    return 1.0 - (counts * (counts - 1.0)).sum(axis=1) / (k * (k - 1.0))


def neighbour_variance(values: np.ndarray) -> np.ndarray:
    """Variance of each row of neighbour scores (shape (p, k)), the σ_K of eq. 3.5."""
    values = np.asarray(values, dtype=float)
    if values.ndim != 2:
        raise InputError(f"values: expected a 2-D array (queries, neighbours), got shape {values.shape}")
    return values.var(axis=1)


def nndv_information(
    spread: np.ndarray, mean_distance: np.ndarray, g: float = 1.0, v: float = 1.0, floor: float = 0.0
) -> np.ndarray:
    """Eq. 3.5: ``(spread + floor)^g · mean_distance^v``."""
    spread = np.asarray(spread, dtype=float)
    mean_distance = np.asarray(mean_distance, dtype=float)
    return np.power(spread + floor, g) * np.power(mean_distance, v)


def gpr_information(gradient_norm: np.ndarray, std: np.ndarray, g: float = 1.0, v: float = 1.0) -> np.ndarray:
    """Eq. 3.4: ``|∇μ|^g · σ^v`` from a Gaussian process's mean gradient and predictive std."""
    return np.power(np.asarray(gradient_norm, dtype=float), g) * np.power(np.asarray(std, dtype=float), v)
