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

__all__ = ["performance_modes", "mean_shift_normalised"]


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
    lo, hi = Yc.min(axis=0), Yc.max(axis=0)
    if np.all(hi <= lo):
        return np.zeros(Yc.shape[0], dtype=np.int64)
    span = np.where(hi > lo, hi - lo, 1.0)
    return mean_shift_normalised((Yc - lo) / span, bandwidth, bin_seeding)


#: Up to this many distinct rows, mean shift runs as a few dense numpy iterations: a
#: sub-boundary tree clusters thousands of small parents, where scikit-learn's per-call
#: overhead (~5 ms) would dominate.
MEAN_SHIFT_MAX_FIT = 2000  # distinct rows a mean-shift fit sees (see mean_shift_normalised)
SMALL_MEAN_SHIFT = 256


def _small_mean_shift(Z: np.ndarray, bandwidth: float, max_iter: int = 300) -> np.ndarray:
    """Flat-kernel mean shift seeded at every row, as scikit-learn's ``MeanShift`` does it.

    Each seed moves to the mean of the rows within ``bandwidth`` until it stops; centres are
    kept in order of how many rows they hold, dropping any within ``bandwidth`` of a kept
    one; rows take their nearest centre.  Labels are numbered by centre (lexicographic).
    """
    d2 = lambda a, b: ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)
    centres = Z.copy()
    for _ in range(max_iter):
        near = d2(centres, Z) <= bandwidth ** 2
        new = (near @ Z) / near.sum(axis=1, keepdims=True)
        moved = np.abs(new - centres).max()
        centres = new
        if moved <= 1e-3 * bandwidth:
            break
    intensity = (d2(centres, Z) <= bandwidth ** 2).sum(axis=1)
    order = np.lexsort((*centres.T[::-1], -intensity))  # most populated first, ties by position
    kept: list[int] = []
    for i in order:
        if not kept or np.all(((centres[kept] - centres[i]) ** 2).sum(-1) > bandwidth ** 2):
            kept.append(int(i))
    c = centres[kept]
    labels = np.argmin(d2(Z, c), axis=1)
    rank = np.empty(len(kept), dtype=np.int64)
    rank[np.lexsort(c.T[::-1])] = np.arange(len(kept))
    return rank[labels]


def mean_shift_normalised(Z: np.ndarray, bandwidth: float, bin_seeding: bool = True) -> np.ndarray:
    """Flat-kernel mean-shift labels of scores already normalised to a common scale.

    Callers that cluster many subsets (a sub-boundary tree's parents) normalise once over
    all samples, so ``bandwidth`` means the same in every subset.  Labels are numbered by
    cluster centre, so they do not depend on seeding order.
    """
    import warnings

    from sklearn.cluster import MeanShift

    if Z.shape[0] <= 1 or np.ptp(Z, axis=0).max() <= bandwidth / 2:
        return np.zeros(Z.shape[0], dtype=np.int64)  # all within one kernel: one cluster
    # Identical score rows are clustered once: simulations often repeat exact scores.
    uniq, inverse = np.unique(Z, axis=0, return_inverse=True)
    if uniq.shape[0] == 1:
        return np.zeros(Z.shape[0], dtype=np.int64)
    if uniq.shape[0] <= SMALL_MEAN_SHIFT:
        labels = _small_mean_shift(uniq, bandwidth)
        return labels[inverse.reshape(-1)]
    # Centres come from at most MEAN_SHIFT_MAX_FIT distinct rows (a seeded subset): in many
    # score columns bin seeding leaves about one seed per row, so a full fit grows as n^2
    # (minutes per parent at 10^5 runs); every row then joins its nearest centre, which is
    # what cluster_all does with the rows of a full fit anyway.
    fit = uniq
    if uniq.shape[0] > MEAN_SHIFT_MAX_FIT:
        fit = uniq[np.sort(np.random.default_rng(0).choice(uniq.shape[0], MEAN_SHIFT_MAX_FIT, replace=False))]
    # Bin seeding is what makes many rows fast; with few rows in many columns a bin centre
    # can lie farther than the bandwidth from every row, so then seed from the rows themselves.
    seeding = bin_seeding and fit.shape[0] > 1000
    ms = MeanShift(bandwidth=bandwidth, bin_seeding=seeding, cluster_all=True, n_jobs=1)
    with warnings.catch_warnings():  # too few points for bin seeding: sklearn seeds from the points
        warnings.filterwarnings("ignore", message="Binning data failed", category=UserWarning)
        try:
            ms.fit(fit)
        except ValueError:  # no row within the bandwidth of any bin centre
            ms = MeanShift(bandwidth=bandwidth, bin_seeding=False, cluster_all=True, n_jobs=1).fit(fit)
    labels = ms.labels_ if fit is uniq else ms.predict(uniq)
    order = np.lexsort(ms.cluster_centers_.T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[labels][inverse.reshape(-1)]
