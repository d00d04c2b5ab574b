"""Performance modes: the discrete kinds of behaviour scores fall into (section 3.5.2).

Discrete scores (pass/fail, mode labels) define modes directly: a mode is one
combination of labels.  Continuous scores have no labels, so they are clustered with
flat-kernel mean shift on min-max normalised scores with bandwidth ``λ_P``; mean shift
needs no number of clusters in advance, and normalisation makes one bandwidth serve
every score.  Mixed score sets combine both: a mode is a combination of discrete labels
and a continuous cluster.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rapt.scores import check_output_types, infer_output_types
from rapt.validation import check_scores

__all__ = ["performance_modes"]


def performance_modes(Y: np.ndarray, output_types: Sequence[str] | None = None, *, bandwidth: float = 0.2,
                      bin_seeding: bool = True) -> np.ndarray:
    """Label each score row with its performance mode (integers ``0..P-1``).

    Parameters
    ----------
    Y:
        (N, m) scores, or (N,) for a single score.
    output_types:
        Per column ``categorical``, ``binary`` or ``continuous``; inferred when omitted.
    bandwidth:
        ``λ_P``, the mean-shift bandwidth on normalised continuous scores.
    bin_seeding:
        Seed mean shift from a grid of bins (fast at a million samples).

    Modes are numbered in the lexicographic order of their defining labels, so the same
    scores always give the same numbering.
    """
    Y = check_scores(Y)
    if not np.isfinite(bandwidth) or bandwidth <= 0:
        raise ValueError(f"bandwidth: expected a number > 0, got {bandwidth!r}")
    types = infer_output_types(Y) if output_types is None else check_output_types(output_types, Y.shape[1])
    discrete = [j for j, t in enumerate(types) if t != "continuous"]
    continuous = [j for j, t in enumerate(types) if t == "continuous"]
    columns = [Y[:, discrete]] if discrete else []
    if continuous:
        columns.append(_mean_shift_labels(Y[:, continuous], bandwidth, bin_seeding)[:, None].astype(float))
    keys = np.hstack(columns)
    _, labels = np.unique(keys, axis=0, return_inverse=True)
    return labels.reshape(-1).astype(np.int64)


def _mean_shift_labels(Yc: np.ndarray, bandwidth: float, bin_seeding: bool) -> np.ndarray:
    from sklearn.cluster import MeanShift

    lo, hi = Yc.min(axis=0), Yc.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    Z = (Yc - lo) / span
    if np.all(hi <= lo):
        return np.zeros(Yc.shape[0], dtype=np.int64)
    # Identical score rows are clustered once: simulations often repeat exact scores.
    uniq, inverse = np.unique(Z, axis=0, return_inverse=True)
    if uniq.shape[0] == 1:
        return np.zeros(Yc.shape[0], dtype=np.int64)
    ms = MeanShift(bandwidth=bandwidth, bin_seeding=bin_seeding, cluster_all=True, n_jobs=1)
    ms.fit(uniq)
    # Number clusters by their centre (lexicographic) so labels do not depend on seeding order.
    order = np.lexsort(ms.cluster_centers_.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[ms.labels_][inverse.reshape(-1)]
