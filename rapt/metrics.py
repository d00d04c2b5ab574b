"""Quality of a boundary search against a system with known boundaries (section 3.6.2).

Plain functions in the style of ``sklearn.metrics``: each takes a system that exposes
``dim``, ``n_outputs``, ``active_dims`` and ``boundary_distance(X)`` (every system in
:mod:`rapt.testfunctions` does), the samples ``X`` a search produced (in the order it
produced them), and the boundary width ``d_eps`` (``D_eps`` in the dissertation).
Results are per output: each output has its own boundary, measured in its own active
subspace.

* precision - fraction of samples inside the boundary band ``B = {x : d(x) < d_eps}``;
* coverage - ``vol(S) / vol(B)``, the sampled share of the band (definition viii);
* mean distance - average distance of the samples to the boundary;
* convergence - samples needed before coverage first reaches a target.
"""

from __future__ import annotations

import numbers

import numpy as np
from scipy.spatial import cKDTree

from rapt.errors import InputError

__all__ = [
    "boundary_precision",
    "boundary_coverage",
    "coverage_curve",
    "mean_boundary_distance",
    "convergence",
    "quality_table",
    "band_reference_points",
]

_MAX_BATCH = 1_000_000  # rejection-sampling batch cap (rows), bounds memory
_PAIR_CHUNK = 20_000  # in-band samples per pair query in coverage_curve


# ------------------------------------------------------------------------ validation
def _check_X(system, X) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != system.dim:
        raise InputError(f"X must be a 2-D array of shape (n, {system.dim}) (system.dim columns); got shape {X.shape}")
    return X


def _check_d_eps(d_eps) -> float:
    if isinstance(d_eps, bool) or not isinstance(d_eps, numbers.Real) or not np.isfinite(float(d_eps)) or d_eps <= 0:
        raise InputError(f"d_eps must be a finite number > 0, got {d_eps!r}")
    return float(d_eps)


def _check_positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise InputError(f"{name} must be an integer >= 1, got {value!r}")
    return int(value)


def _distances(system, X: np.ndarray) -> np.ndarray:
    if X.shape[0] == 0:
        return np.empty((0, system.n_outputs))
    return np.asarray(system.boundary_distance(X), dtype=float).reshape(X.shape[0], -1)


# --------------------------------------------------------------------------- metrics
def boundary_precision(system, X, d_eps) -> np.ndarray:
    """Precision per output: ``P_i = #{j : d_i(X_j) < d_eps} / N``.

    ``d_i`` is the exact distance to output ``i``'s boundary in its active subspace, so
    ``P_i`` is the fraction of the ``N`` samples that lie in the boundary band ``B_i``.
    For uniform samples ``P_i`` estimates ``vol(B_i)`` (the band fraction).  Returns an
    array of shape ``(n_outputs,)``; NaN when ``X`` has no rows.
    """
    X = _check_X(system, X)
    d_eps = _check_d_eps(d_eps)
    if X.shape[0] == 0:
        return np.full(system.n_outputs, np.nan)
    return (_distances(system, X) < d_eps).mean(axis=0)


def mean_boundary_distance(system, X) -> np.ndarray:
    """Mean distance per output: ``m_i = (1 / N) * sum_j d_i(X_j)``.

    Returns an array of shape ``(n_outputs,)``; NaN when ``X`` has no rows.
    """
    X = _check_X(system, X)
    if X.shape[0] == 0:
        return np.full(system.n_outputs, np.nan)
    return _distances(system, X).mean(axis=0)


def band_reference_points(system, d_eps, n_reference=20000, seed=0, max_draws=None):
    """Uniform points of each output's boundary band, in that output's active subspace.

    For output ``i`` with active columns ``a_i`` (``k_i`` of them), points are drawn
    uniformly in ``[0, 1]^k_i`` and kept when ``d_i < d_eps`` until ``n_reference`` are
    kept or ``max_draws`` (default ``500 * n_reference``) have been drawn.  The other
    input columns are set to 0.5, which is harmless because ``d_i`` only depends on
    ``a_i``.  Returns a list of ``(m_i, k_i)`` arrays (``m_i <= n_reference``; 0 rows if
    the band was never hit).  Deterministic given ``seed`` (one child stream per output).
    """
    d_eps = _check_d_eps(d_eps)
    n_reference = _check_positive_int(n_reference, "n_reference")
    max_draws = 500 * n_reference if max_draws is None else _check_positive_int(max_draws, "max_draws")
    streams = np.random.SeedSequence(seed).spawn(system.n_outputs)
    refs = []
    for i, stream in enumerate(streams):
        rng = np.random.default_rng(stream)
        active = list(system.active_dims[i])
        kept, n_kept, drawn = [], 0, 0
        batch = max(4 * n_reference, 10_000)
        while n_kept < n_reference and drawn < max_draws:
            b = int(min(batch, max_draws - drawn, _MAX_BATCH))
            U = rng.random((b, len(active)))
            full = np.full((b, system.dim), 0.5)
            full[:, active] = U
            keep = _distances(system, full)[:, i] < d_eps
            kept.append(U[keep])
            n_kept += int(keep.sum())
            drawn += b
            frac = n_kept / drawn
            batch = int(1.2 * (n_reference - n_kept) / frac) + 1000 if frac > 0 else 4 * b
        R = np.concatenate(kept) if kept else np.empty((0, len(active)))
        refs.append(R[:n_reference])
    return refs


def _first_cover_index(ref: np.ndarray, P: np.ndarray, idx: np.ndarray, d_eps: float) -> np.ndarray:
    """For every reference point, the smallest sample index ``idx[j]`` with ``|ref - P_j| < d_eps``.

    Reference points never covered get ``np.iinfo(np.int64).max``.
    """
    never = np.iinfo(np.int64).max
    first = np.full(len(ref), never, dtype=np.int64)
    if len(ref) == 0 or len(P) == 0:
        return first
    ref_tree = cKDTree(ref)
    for lo in range(0, len(P), _PAIR_CHUNK):
        chunk = cKDTree(P[lo : lo + _PAIR_CHUNK])
        pairs = chunk.sparse_distance_matrix(ref_tree, d_eps, output_type="ndarray")
        pairs = pairs[pairs["v"] < d_eps]
        np.minimum.at(first, pairs["j"], idx[lo + pairs["i"]])
    return first


def coverage_curve(system, X, d_eps, sizes, n_reference=20000, seed=0, max_draws=None) -> np.ndarray:
    """Coverage of the prefixes ``X[:n]`` for every ``n`` in ``sizes``: shape ``(len(sizes), n_outputs)``.

    Uses the same reference points for every prefix (so the curve is non-decreasing);
    the last row for ``n = len(X)`` equals :func:`boundary_coverage` with the same
    ``seed``.  See :func:`boundary_coverage` for the formula.
    """
    X = _check_X(system, X)
    d_eps = _check_d_eps(d_eps)
    sizes = np.asarray(sizes, dtype=np.int64).reshape(-1)
    if np.any(sizes < 0):
        raise InputError(f"sizes must be non-negative prefix lengths, got {sizes.tolist()}")
    refs = band_reference_points(system, d_eps, n_reference, seed, max_draws)
    dist = _distances(system, X)
    curve = np.empty((len(sizes), system.n_outputs))
    for i, ref in enumerate(refs):
        if len(ref) == 0:
            curve[:, i] = np.nan
            continue
        idx = np.flatnonzero(dist[:, i] < d_eps)
        P = X[idx][:, list(system.active_dims[i])]
        first = np.sort(_first_cover_index(ref, P, idx, d_eps))
        curve[:, i] = np.searchsorted(first, sizes, side="left") / len(ref)
    return curve


def boundary_coverage(system, X, d_eps, n_reference=20000, seed=0, max_draws=None) -> np.ndarray:
    """Coverage per output: ``C_i = vol(S_i) / vol(B_i)`` (definition viii, section 3.3.1).

    ``B_i = {x : d_i(x) < d_eps}`` is the boundary band of output ``i`` in its active
    subspace and ``S_i = {x in B_i : exists X_j in B_i with |x - X_j| < d_eps}`` is the
    part of the band within ``d_eps`` of an in-band sample (distances in the active
    subspace).  Monte Carlo estimate: ``C_i ~= #{r in R_i : r in S_i} / |R_i|`` with
    ``R_i`` uniform reference points of ``B_i`` (:func:`band_reference_points`, up to
    ``n_reference`` per output), counted with a ``cKDTree`` of the in-band samples.
    Deterministic given ``seed``.  Returns ``(n_outputs,)``; 0 when no sample is in the
    band, NaN when no reference point hit the band.
    """
    X = _check_X(system, X)
    d_eps = _check_d_eps(d_eps)
    refs = band_reference_points(system, d_eps, n_reference, seed, max_draws)
    dist = _distances(system, X)
    out = np.empty(system.n_outputs)
    for i, ref in enumerate(refs):
        if len(ref) == 0:
            out[i] = np.nan
            continue
        P = X[dist[:, i] < d_eps][:, list(system.active_dims[i])]
        if len(P) == 0:
            out[i] = 0.0
            continue
        nearest, _ = cKDTree(P).query(ref, k=1, distance_upper_bound=d_eps)
        out[i] = np.mean(nearest < d_eps)
    return out


def convergence(system, X, d_eps, target=0.9, step=None, **coverage_kw) -> np.ndarray:
    """Samples needed per output: ``min {n in grid : C_i(X[:n]) >= target}``.

    The grid is ``step, 2*step, ...`` plus ``len(X)`` (default ``step = max(len(X) // 20, 1)``);
    ``X`` must be in the order the search produced it.  ``coverage_kw`` (``n_reference``,
    ``seed``, ``max_draws``) go to :func:`coverage_curve`.  Returns float ``(n_outputs,)``
    with NaN where coverage never reaches ``target`` within ``len(X)`` samples.
    """
    X = _check_X(system, X)
    d_eps = _check_d_eps(d_eps)
    if isinstance(target, bool) or not isinstance(target, numbers.Real) or not 0 < float(target) <= 1:
        raise InputError(f"target must be a coverage fraction in (0, 1], got {target!r}")
    n = X.shape[0]
    step = max(n // 20, 1) if step is None else _check_positive_int(step, "step")
    if n == 0:
        return np.full(system.n_outputs, np.nan)
    sizes = np.arange(step, n + 1, step)
    if len(sizes) == 0 or sizes[-1] != n:
        sizes = np.append(sizes, n)
    curve = coverage_curve(system, X, d_eps, sizes, **coverage_kw)
    out = np.full(system.n_outputs, np.nan)
    for i in range(system.n_outputs):
        hit = np.flatnonzero(curve[:, i] >= target)
        if len(hit):
            out[i] = float(sizes[hit[0]])
    return out


def quality_table(system, X, d_eps, seed=0, n_reference=20000) -> dict:
    """Precision, coverage and mean distance of a sample set, averaged over outputs.

    Returns ``{"precision": float, "coverage": float, "mean_distance": float,
    "per_output": {"precision": array, "coverage": array, "mean_distance": array},
    "n_samples": int, "d_eps": float}``; the floats are the means over outputs of
    :func:`boundary_precision`, :func:`boundary_coverage` and
    :func:`mean_boundary_distance`.
    """
    X = _check_X(system, X)
    d_eps = _check_d_eps(d_eps)
    per = {
        "precision": boundary_precision(system, X, d_eps),
        "coverage": boundary_coverage(system, X, d_eps, n_reference=n_reference, seed=seed),
        "mean_distance": mean_boundary_distance(system, X),
    }
    table: dict[str, float | dict[str, np.ndarray]] = {key: float(np.mean(val)) for key, val in per.items()}
    table["per_output"] = per
    table["n_samples"] = int(X.shape[0])
    table["d_eps"] = d_eps
    return table


def subboundary_recovery(
    system, subtree, *, grid: int = 512, tol: float = 0.05, quantile: float | None = None
) -> list[dict]:
    """How well a sub-boundary tree matches a 2-D system's true sub-boundaries, per level.

    Ground truth comes from a ``grid × grid`` raster of the system's scores: at level ``l``
    a sample's key is its values of every score column of levels ``0..l``; a true
    sub-boundary type is an unordered pair of keys that meet at adjacent cells sharing the
    same level ``l-1`` key (the same parent cluster).  A type is *recovered* when the tree
    has a pair of that type shorter than ``tol``; a reported pair is *on a true boundary*
    when its midpoint is within ``tol`` of a grid edge of its type.  With ``quantile``,
    only each level's pairs up to that distance quantile count as reported (eq. 3.11).
    Returns one dict per level: ``true_types``, ``recovered``, ``recovered_fraction``,
    ``pairs``, ``on_boundary_fraction``.
    """
    if system.dim != 2:
        raise InputError(f"system: sub-boundary ground truth is rasterised in 2-D; got dim={system.dim}")
    g = _check_positive_int(grid, "grid")
    c = (np.arange(g) + 0.5) / g
    xx, yy = np.meshgrid(c, c, indexing="ij")
    cells = np.column_stack([xx.ravel(), yy.ravel()])
    V = system(cells)
    levels = subtree.levels
    out = []
    for lv in range(len(levels)):
        cols = [k for level in levels[: lv + 1] for k in level]
        parent_cols = [k for level in levels[:lv] for k in level]
        # Reported pairs first, so grid cells and pair endpoints share one row coding.
        i, j, d, _ = subtree.pairs(lv)
        if quantile is not None and d.size:
            keep = d <= np.quantile(d, quantile)
            i, j, d = i[keep], j[keep], d[keep]
        codes = _row_codes(np.vstack([V[:, cols], subtree.Y[i][:, cols], subtree.Y[j][:, cols]]))
        key_grid = codes[: g * g].reshape(g, g)
        ki, kj = codes[g * g : g * g + i.size], codes[g * g + i.size :]
        parent_grid = _row_codes(V[:, parent_cols]).reshape(g, g) if parent_cols else np.zeros((g, g), dtype=np.int64)
        edges: dict[tuple[int, int], list[np.ndarray]] = {}
        for axis in (0, 1):
            a = key_grid[:-1, :] if axis == 0 else key_grid[:, :-1]
            b = key_grid[1:, :] if axis == 0 else key_grid[:, 1:]
            pa = parent_grid[:-1, :] if axis == 0 else parent_grid[:, :-1]
            pb = parent_grid[1:, :] if axis == 0 else parent_grid[:, 1:]
            where = np.argwhere((a != b) & (pa == pb))
            if where.size == 0:
                continue
            ka, kb = a[where[:, 0], where[:, 1]], b[where[:, 0], where[:, 1]]
            # midpoint of the edge between the two cells, in unit coordinates
            mid = (where + (np.array([1.0, 0.5]) if axis == 0 else np.array([0.5, 1.0]))) / g
            lo, hi = np.minimum(ka, kb), np.maximum(ka, kb)
            for t in np.unique(np.column_stack([lo, hi]), axis=0):
                sel = (lo == t[0]) & (hi == t[1])
                edges.setdefault((int(t[0]), int(t[1])), []).append(mid[sel])
        trees = {t: cKDTree(np.vstack(p)) for t, p in edges.items()}
        recovered = 0
        for ta, tb in trees:
            hit = ((np.minimum(ki, kj) == ta) & (np.maximum(ki, kj) == tb)) & (d < tol)
            recovered += bool(np.any(hit))
        on = np.zeros(i.size, dtype=bool)
        mid = (subtree.X[i] + subtree.X[j]) / 2.0
        for (ta, tb), tree in trees.items():
            sel = (np.minimum(ki, kj) == ta) & (np.maximum(ki, kj) == tb)
            if np.any(sel):
                on[sel] = tree.query(mid[sel], k=1)[0] < tol
        out.append(
            {
                "level": lv,
                "true_types": len(trees),
                "recovered": recovered,
                "recovered_fraction": recovered / len(trees) if trees else float("nan"),
                "pairs": int(i.size),
                "on_boundary_fraction": float(on.mean()) if i.size else float("nan"),
            }
        )
    return out


def _row_codes(A: np.ndarray) -> np.ndarray:
    """Integer code of each row: equal rows get equal codes."""
    return np.unique(A, axis=0, return_inverse=True)[1].reshape(-1).astype(np.int64)
