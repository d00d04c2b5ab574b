"""Performance modes: the discrete kinds of behaviour scores fall into (section 3.5.2).

Discrete scores (pass/fail, mode labels) define modes directly: a mode is one
combination of labels.  Continuous scores have no labels, so they are clustered with
flat-kernel mean shift on min-max normalised scores with bandwidth ``λ_P``; mean shift
needs no number of clusters in advance, and normalisation makes one bandwidth serve
every score.  Mixed score sets combine both: a mode is a combination of discrete labels
and a continuous cluster.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rapt.errors import InputError
from rapt.scores import check_output_types, infer_output_types
from rapt.validation import check_scores

__all__ = ["performance_modes", "mean_shift_normalised"]


def performance_modes(
    Y: np.ndarray, output_types: Sequence[str] | None = None, *, bandwidth: float = 0.2, bin_seeding: bool = True
) -> np.ndarray:
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
        raise InputError(f"bandwidth: expected a number > 0, got {bandwidth!r}")
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


#: Mean shift runs as dense numpy iterations on at most this many distinct rows: a
#: sub-boundary tree clusters thousands of parents, where scikit-learn's fixed cost per
#: call and per fit outweighs the small clustering work, and in many score columns bin
#: seeding leaves about one seed per row, so a full fit grows as n^2.  Larger sets fit their centres on
#: a seeded subset of this size and every row joins its nearest centre — what
#: ``cluster_all`` does with the rows of a full fit anyway.
MEAN_SHIFT_MAX_FIT = 2000
BIN_SEEDING_ABOVE = 1000  # distinct rows above which bins seed the shift


def _sq_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared Euclidean distances (len(a), len(b)) through one matrix product."""
    d = (a * a).sum(1)[:, None] + (b * b).sum(1)[None, :] - 2.0 * (a @ b.T)
    return np.maximum(d, 0.0)


def _small_mean_shift(Z: np.ndarray, bandwidth: float, max_iter: int = 300) -> np.ndarray:
    """Flat-kernel mean shift seeded at every row, as scikit-learn's ``MeanShift`` does it.

    Each seed moves to the mean of the rows within ``bandwidth`` until it stops; centres are
    kept in order of how many rows they hold, dropping any within ``bandwidth`` of a kept
    one; rows take their nearest centre.  Labels are numbered by centre (lexicographic).
    """
    centres, intensity = _shift_seeds(Z, bandwidth, max_iter)
    return _nearest_centre_labels(Z, centres, bandwidth, intensity)


def _shift_seeds(
    Z: np.ndarray, bandwidth: float, max_iter: int, seeds: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Seeds (default: every row of ``Z``) shifted to convergence; returns (centres, rows within bandwidth of each)."""
    b2 = bandwidth**2
    centres = (Z if seeds is None else seeds).astype(float, copy=True)
    for _ in range(max_iter):
        near = (_sq_distances(centres, Z) <= b2).astype(float)
        count = near.sum(axis=1, keepdims=True)
        new = np.where(count > 0, (near @ Z) / np.maximum(count, 1.0), centres)  # a lone seed stays put
        moved = np.abs(new - centres).max()
        centres = new
        if moved <= 1e-3 * bandwidth:
            break
    intensity = (_sq_distances(centres, Z) <= b2).sum(axis=1)
    return centres[intensity > 0], intensity[intensity > 0]  # seeds no row reached are dropped


def _nearest_centre_labels(
    Z: np.ndarray, centres: np.ndarray, bandwidth: float, intensity: np.ndarray, rows: np.ndarray | None = None
) -> np.ndarray:
    """Deduplicate converged seeds (most populated first) and label ``rows`` (default ``Z``) by nearest centre."""
    order = np.lexsort((*centres.T[::-1], -intensity))  # most populated first, ties by position
    kept: list[int] = []
    for i in order:
        if not kept or np.all(((centres[kept] - centres[i]) ** 2).sum(-1) > bandwidth**2):
            kept.append(int(i))
    c = centres[kept]
    labels = np.argmin(_sq_distances(Z if rows is None else rows, c), axis=1)
    rank = np.empty(len(kept), dtype=np.int64)
    rank[np.lexsort(c.T[::-1])] = np.arange(len(kept))
    return rank[labels]


def mean_shift_normalised(Z: np.ndarray, bandwidth: float, bin_seeding: bool = True) -> np.ndarray:
    """Flat-kernel mean-shift labels of scores already normalised to a common scale.

    Callers that cluster many subsets (a sub-boundary tree's parents) normalise once over
    all samples, so ``bandwidth`` means the same in every subset.  Labels are numbered by
    cluster centre, so they do not depend on seeding order.
    With ``bin_seeding``, the centres of the occupied cells of a grid of side ``bandwidth``
    seed the shift, and seeds no row is within reach of are dropped, as in scikit-learn's
    ``bin_seeding``: far fewer seeds than rows in a few score columns, and in many columns
    isolated rows join the nearest centre instead of founding clusters of one.
    """
    if Z.shape[0] <= 1 or np.ptp(Z, axis=0).max() <= bandwidth / 2:
        return np.zeros(Z.shape[0], dtype=np.int64)  # all within one kernel: one cluster
    # Identical score rows are clustered once: simulations often repeat exact scores.
    uniq, inverse = np.unique(Z, axis=0, return_inverse=True)
    if uniq.shape[0] == 1:
        return np.zeros(Z.shape[0], dtype=np.int64)
    fit = uniq
    if uniq.shape[0] > MEAN_SHIFT_MAX_FIT:
        fit = uniq[np.sort(np.random.default_rng(0).choice(uniq.shape[0], MEAN_SHIFT_MAX_FIT, replace=False))]
    # Bins only pay off with many rows; with few, seed from every row (as the old fits did).
    binned = bin_seeding and fit.shape[0] > BIN_SEEDING_ABOVE
    seeds = np.unique(np.round(fit / bandwidth), axis=0) * bandwidth if binned else None
    centres, intensity = _shift_seeds(fit, bandwidth, 300, seeds)
    if centres.shape[0] == 0:  # no row within the bandwidth of any cell centre: seed from the rows
        centres, intensity = _shift_seeds(fit, bandwidth, 300)
    labels = _nearest_centre_labels(fit, centres, bandwidth, intensity, rows=uniq)
    return labels[inverse.reshape(-1)]
