"""Boundary pairs: samples on either side of a performance boundary (sections 3.5.2-3.5.4).

A boundary pair is two samples in different modes that are each other's nearest
neighbour in the other's mode (definition vii; Algorithm 3's two nearest-neighbour
searches).  Pairs are ranked by distance — the closer, the more precisely the pair pins
the boundary — and typed by the two modes they join.  Two thresholds prune them: the
absolute width ``D_eps`` (eq. 3.10) and the per-type quantile ``q_B`` (eq. 3.11).

Inside each mode, DBSCAN groups samples into contiguous clusters; a pair with an endpoint
that DBSCAN calls noise (isolated in its mode) is marked ``likely_noise``: with a noisy
simulator a lone sample of the "wrong" mode creates pairs that are not behaviour changes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from rapt.errors import InputError
from rapt.modes import performance_modes
from rapt.parallel import query_workers
from rapt.validation import check_scores, check_states

__all__ = [
    "BoundaryPairs",
    "boundary_pairs",
    "mutual_pairs",
    "knn_graph",
    "exact_order",
    "graph_mutual_pairs",
    "pair_differences",
]


@dataclass
class BoundaryPairs:
    """Boundary pairs sorted by ascending distance.

    ``i``/``j`` index the samples (``mode_i < mode_j``); ``cluster_i``/``cluster_j`` are
    the DBSCAN clusters of the endpoints inside their modes (-1: noise; all 0 when
    clustering was not requested).
    """

    i: np.ndarray
    j: np.ndarray
    distance: np.ndarray
    mode_i: np.ndarray
    mode_j: np.ndarray
    cluster_i: np.ndarray
    cluster_j: np.ndarray
    likely_noise: np.ndarray
    labels: np.ndarray = field(repr=False)

    def __len__(self) -> int:
        return int(self.i.shape[0])

    def types(self) -> list[tuple[int, int, int]]:
        """Boundary types present as ``(mode_a, mode_b, number of pairs)``."""
        if len(self) == 0:
            return []
        keys, counts = np.unique(np.column_stack([self.mode_i, self.mode_j]), axis=0, return_counts=True)
        return [(int(a), int(b), int(c)) for (a, b), c in zip(keys, counts)]

    def select(self, mask: np.ndarray) -> BoundaryPairs:
        mask = np.asarray(mask)
        return BoundaryPairs(
            self.i[mask],
            self.j[mask],
            self.distance[mask],
            self.mode_i[mask],
            self.mode_j[mask],
            self.cluster_i[mask],
            self.cluster_j[mask],
            self.likely_noise[mask],
            self.labels,
        )

    def of_type(self, mode_a: int, mode_b: int) -> BoundaryPairs:
        a, b = min(mode_a, mode_b), max(mode_a, mode_b)
        return self.select((self.mode_i == a) & (self.mode_j == b))


def mutual_pairs(
    X: np.ndarray, labels: np.ndarray, groups: Sequence[int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mutual nearest neighbours across every pair of label groups.

    For groups ``a < b``: ``x ∈ a`` and ``y ∈ b`` form a pair when ``y`` is ``x``'s nearest
    neighbour in ``b`` and ``x`` is ``y``'s nearest neighbour in ``a``.  Returns (i, j, d)
    with ``labels[i] < labels[j]``, unsorted.
    """
    group_ids = np.unique(labels) if groups is None else np.asarray(groups)
    members = {int(g): np.flatnonzero(labels == g) for g in group_ids}
    trees = {g: cKDTree(X[idx]) for g, idx in members.items() if idx.size}
    out_i, out_j, out_d = [], [], []
    keys = sorted(trees)
    for ai, a in enumerate(keys):
        for b in keys[ai + 1 :]:
            ia, ib = members[a], members[b]
            d_ab, nn_ab = trees[b].query(
                X[ia], k=1, workers=query_workers(ia.size)
            )  # for each a: nearest b (local index)
            _, nn_ba = trees[a].query(X[ib], k=1, workers=query_workers(ib.size))  # for each b: nearest a (local index)
            mutual = nn_ba[nn_ab] == np.arange(ia.size)
            out_i.append(ia[mutual])
            out_j.append(ib[nn_ab[mutual]])
            out_d.append(d_ab[mutual])
    if not out_i:
        empty = np.empty(0, dtype=np.int64)
        return empty, empty, np.empty(0)
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_d)


#: Below this many samples (or at most this many inputs) the exact k-d tree is cheap enough.
EXACT_GRAPH_MAX_SAMPLES = 20_000
EXACT_GRAPH_MAX_DIM = 6


def knn_graph(X: np.ndarray, k: int, method: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """Each sample's ``k`` nearest other samples: (distances, indices), both (N, k), nearest first.

    ``k`` is capped at ``N - 1``; with ``k = N - 1`` the graph is complete.
    ``method``: ``"exact"`` (scipy k-d tree), ``"hnsw"`` (faiss's hierarchical navigable
    small-world graph, approximate) or ``"auto"``: exact for small or low-dimensional sets,
    HNSW otherwise.  In 10+ dimensions an exact k-d tree degrades to brute force, whose
    cost grows with the square of the samples.  HNSW misses some of the exact neighbours,
    more of them in larger sets, but a pair it misses is mostly replaced by an equally
    short neighbour across the same boundary, which is all the pairing needs.
    ``benchmarks/boundaries.py`` measures the time and recall of both.
    """
    if method not in ("auto", "exact", "hnsw"):
        raise InputError(f"method: expected 'auto', 'exact' or 'hnsw', got {method!r}")
    n, d = X.shape
    k = int(min(k, n - 1))
    if k < 1:
        return np.empty((n, 0)), np.empty((n, 0), dtype=np.int64)
    if method == "auto":
        method = "exact" if n <= EXACT_GRAPH_MAX_SAMPLES or d <= EXACT_GRAPH_MAX_DIM else "hnsw"
    if method == "hnsw":
        dist, idx = _hnsw_query(X, k + 1)
    else:
        dist, idx = cKDTree(X).query(X, k=k + 1, workers=query_workers(n))
    dist, idx = np.atleast_2d(dist), np.atleast_2d(idx)
    # Drop each row's own index (normally column 0; with duplicate points it may sit later).
    own = idx == np.arange(n)[:, None]
    drop = np.where(own.any(axis=1), own.argmax(axis=1), k)
    keep = np.ones_like(own)
    keep[np.arange(n), drop] = False
    return dist[keep].reshape(n, k), idx[keep].reshape(n, k).astype(np.int64)


def exact_order(X: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's neighbours ``idx`` with their exact distances in ``X``, nearest first.

    An approximate graph (HNSW, or one stored in float32) holds the right neighbours in a
    slightly wrong order; pairing through it needs each row's exact order and distances.
    A row's own index (padding of a short list) gets an infinite distance.
    """
    n, k = idx.shape
    d = np.empty(idx.shape)
    for s in range(0, n, 65_536):  # blocks: (rows, k, dim) differences stay small
        rows = np.arange(s, min(s + 65_536, n))
        diff = X[idx[rows]] - X[rows][:, None, :]
        d[rows] = np.sqrt(np.einsum("rkd,rkd->rk", diff, diff))
    d[idx == np.arange(n)[:, None]] = np.inf
    order = np.argsort(d, axis=1, kind="stable")
    return np.take_along_axis(d, order, axis=1), np.take_along_axis(idx, order, axis=1).astype(np.int64)


#: HNSW graph parameters (faiss): links per node, candidate list while building and while
#: searching.  Chosen with benchmarks/boundaries.py on 10^5-10^6 uniform samples in 18-D:
#: short candidate lists cost clearly less CPU than longer ones and a top-down search, for a
#: slightly lower recall of the exact nearest neighbours, which the boundary pairs tolerate
#: (see :func:`knn_graph`).
HNSW_M = 16
HNSW_EF_CONSTRUCTION = 24
HNSW_EF_SEARCH = 24


def _hnsw_query(
    X: np.ndarray, k: int, m: int = HNSW_M, ef_construction: int = HNSW_EF_CONSTRUCTION, ef_search: int = HNSW_EF_SEARCH
) -> tuple[np.ndarray, np.ndarray]:
    """Approximate k nearest neighbours (self included) of every row from a faiss HNSW index.

    The queries are the indexed points themselves, so each search starts on the bottom
    layer at the point itself (``search_level_0`` with the point as its entry) instead of
    descending the hierarchy from the top: the descent only finds a way to the query,
    which is already known, so skipping it saves that part of the work.
    """
    import faiss

    Xf = np.ascontiguousarray(X, dtype=np.float32)
    n, d = Xf.shape
    index = faiss.IndexHNSWFlat(d, m)
    index.hnsw.efConstruction = ef_construction
    index.add(Xf)
    # SearchParametersHNSW and IndexHNSW.search_level_0 are in faiss but missing from the stubs it ships
    params = faiss.SearchParametersHNSW()  # type: ignore[attr-defined]
    params.efSearch = max(ef_search, k)
    sq = np.empty((n, k), dtype=np.float32)
    idx = np.empty((n, k), dtype=np.int64)
    entry = np.arange(n, dtype=np.int32)  # faiss's storage_idx_t
    entry_d = np.zeros(n, dtype=np.float32)
    index.search_level_0(  # type: ignore[attr-defined]
        n,
        faiss.swig_ptr(Xf),
        k,
        faiss.swig_ptr(entry),
        faiss.swig_ptr(entry_d),
        faiss.swig_ptr(sq),
        faiss.swig_ptr(idx),
        1,
        1,
        params,
    )
    missing = idx < 0  # too few reachable points: fall back to self at infinite distance
    idx = np.where(missing, np.arange(n)[:, None], idx)
    dist = np.sqrt(np.maximum(sq.astype(float), 0.0))
    dist[missing] = np.inf
    return dist, idx


def graph_mutual_pairs(
    dist: np.ndarray, idx: np.ndarray, groups: np.ndarray, parents: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mutual nearest cross-group neighbours within a k-nearest-neighbour graph.

    ``x`` and ``y`` pair when ``y`` is the nearest of ``x``'s graph neighbours in
    ``y``'s group and ``x`` the nearest of ``y``'s in ``x``'s; with ``parents``, only
    samples of the same parent are compared (sub-boundaries inside a cluster).  On a
    complete graph this is exactly :func:`mutual_pairs`; on a k-graph it drops pairs
    longer than both endpoints' k-th neighbour distance, which are not local evidence
    of a boundary.  Vectorised over the graph's columns, O(N k^2) with no sort, however
    many groups there are (a sort per row for wide, e.g. complete, graphs); the columns
    are handled as contiguous (k, N) rows, since a column of an (N, k) array is strided.
    Returns (i, j, d) with ``groups[i] < groups[j]``, ordered by (column, row).
    """
    n, k = idx.shape
    if k == 0:
        e = np.empty(0, dtype=np.int64)
        return e, e, np.empty(0)
    idx_t = np.ascontiguousarray(idx.T)  # (k, N): column c of the graph is row c here
    G = groups[idx_t]
    valid = G != groups[None, :]
    if parents is not None:
        valid &= parents[idx_t] == parents[None, :]
    first = _first_per_group(G, valid)  # (k, N)
    cols, rows = np.nonzero(first & (groups[None, :] < G))
    src, dst = rows.astype(np.int64), idx_t[cols, rows].astype(np.int64)
    # Is src the nearest of dst's neighbours in src's group?  Mark each row's first-per-group
    # neighbours (others -1) and look src up in dst's row: one row gather, no strided columns.
    marked = np.where(first, idx_t, -1).T.copy()  # (N, k)
    mutual = (marked[dst] == src[:, None]).any(axis=1)
    return src[mutual], dst[mutual], dist[rows[mutual], cols[mutual]]


def _first_per_group(G: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``first[c, r]``: column c holds row r's nearest valid neighbour of group ``G[c, r]``.

    ``G`` and ``valid`` are (k, N), graph columns as rows.  Rows of the graph are ordered
    nearest first, so that is the first valid column with that group.
    """
    k, n = G.shape
    if k <= 32:  # pairwise column comparisons: O(N k^2), no sort
        first = valid.copy()
        for c in range(1, k):
            seen = np.zeros(n, dtype=bool)
            for c2 in range(c):
                seen |= valid[c2] & (G[c2] == G[c])
            first[c] &= ~seen
        return first
    # wide rows: stable sort of each graph row by group, keep each group's first valid column
    key = np.where(valid, G, -1).T
    order = np.argsort(key, axis=1, kind="stable")
    sk = np.take_along_axis(key, order, axis=1)
    lead = np.ones(sk.shape, dtype=bool)
    lead[:, 1:] = sk[:, 1:] != sk[:, :-1]
    first = np.zeros(sk.shape, dtype=bool)
    np.put_along_axis(first, order, lead & (sk >= 0), axis=1)
    return np.ascontiguousarray(first.T)


def boundary_pairs(
    X: np.ndarray,
    Y: np.ndarray | None = None,
    *,
    labels: np.ndarray | None = None,
    output_types: Sequence[str] | None = None,
    bandwidth: float = 0.2,
    d_eps: float | None = None,
    quantile: float | None = None,
    weights: np.ndarray | None = None,
    cluster_eps: float | None = None,
    min_samples: int = 20,
) -> BoundaryPairs:
    """Find, threshold and rank the boundary pairs of a labelled sample set (Algorithm 2).

    Parameters
    ----------
    X:
        (N, d) states, normally in the unit cube.
    Y, labels:
        Scores to derive modes from (:func:`rapt.performance_modes`), or the modes directly.
    d_eps:
        Keep pairs closer than this (eq. 3.10).
    quantile:
        ``q_B`` of eq. 3.11: per boundary type, keep pairs no farther than that quantile of
        the type's pair distances (the dissertation uses 0.2).
    weights:
        Per-input scale (e.g. tree importance) — distances are measured in ``X ∘ weights``.
    cluster_eps, min_samples:
        DBSCAN ``ε_C`` and ``n_min`` inside each mode; when given, pairs touching DBSCAN
        noise are marked ``likely_noise``.
    """
    X = check_states(X)
    if (Y is None) == (labels is None):
        raise InputError("Y, labels: give exactly one of scores Y or mode labels")
    if labels is None:
        labels = performance_modes(check_scores(Y, X.shape[0]), output_types, bandwidth=bandwidth)
    else:
        labels = np.asarray(labels).reshape(-1)
        if labels.shape[0] != X.shape[0]:
            raise InputError(f"labels: expected {X.shape[0]} labels (one per state), got {labels.shape[0]}")
        _, labels = np.unique(labels, return_inverse=True)
        labels = labels.reshape(-1)
    if d_eps is not None and not (np.isfinite(d_eps) and d_eps > 0):
        raise InputError(f"d_eps: expected a distance > 0, got {d_eps!r}")
    if quantile is not None and not (0 < quantile <= 1):
        raise InputError(f"quantile: expected q_B in (0, 1], got {quantile!r}")
    if weights is not None:
        weights = np.asarray(weights, dtype=float)
        if weights.shape != (X.shape[1],) or np.any(weights < 0) or not np.all(np.isfinite(weights)):
            raise InputError(f"weights: expected {X.shape[1]} non-negative finite scale factors, got {weights!r}")
        X = X * weights

    i, j, d = mutual_pairs(X, labels)
    keep = np.ones(i.shape[0], dtype=bool)
    if d_eps is not None:
        keep &= d < d_eps
    i, j, d = i[keep], j[keep], d[keep]
    mi, mj = labels[i], labels[j]
    if quantile is not None and i.size:
        keep = np.zeros(i.size, dtype=bool)
        type_key = mi * (labels.max() + 1) + mj
        for key in np.unique(type_key):
            sel = type_key == key
            keep[sel] = d[sel] <= np.quantile(d[sel], quantile)
        i, j, d, mi, mj = i[keep], j[keep], d[keep], mi[keep], mj[keep]

    clusters = np.zeros(X.shape[0], dtype=np.int64)
    if cluster_eps is not None:
        clusters = _dbscan_within_modes(X, labels, cluster_eps, min_samples)
    order = np.lexsort((j, i, d))
    i, j, d, mi, mj = i[order], j[order], d[order], mi[order], mj[order]
    ci, cj = clusters[i], clusters[j]
    return BoundaryPairs(
        i.astype(np.int64),
        j.astype(np.int64),
        d,
        mi.astype(np.int64),
        mj.astype(np.int64),
        ci,
        cj,
        (ci < 0) | (cj < 0),
        labels,
    )


def _dbscan_within_modes(X: np.ndarray, labels: np.ndarray, eps: float, min_samples: int) -> np.ndarray:
    from sklearn.cluster import DBSCAN

    if not (np.isfinite(eps) and eps > 0):
        raise InputError(f"cluster_eps: expected ε_C > 0, got {eps!r}")
    if not isinstance(min_samples, (int, np.integer)) or min_samples < 1:
        raise InputError(f"min_samples: expected a positive integer n_min, got {min_samples!r}")
    out = np.full(X.shape[0], -1, dtype=np.int64)
    for g in np.unique(labels):
        idx = np.flatnonzero(labels == g)
        if idx.size < min_samples:
            continue  # every member is isolated: all noise
        out[idx] = DBSCAN(eps=eps, min_samples=min_samples).fit(X[idx]).labels_
    return out


def pair_differences(X: np.ndarray, pairs: BoundaryPairs, bounds: np.ndarray | None = None) -> np.ndarray:
    """What changed across each pair: ``(X[j] - X[i])`` per input, normalised by the input's range.

    ``X`` in the unit cube needs no ``bounds``; for physical units pass the (d, 2) bounds.
    Rows line up with the pairs, ready for a parallel-coordinates view.
    """
    X = np.asarray(X, dtype=float)
    diff = X[pairs.j] - X[pairs.i]
    if bounds is not None:
        b = np.asarray(bounds, dtype=float)
        if b.shape != (X.shape[1], 2):
            raise InputError(f"bounds: expected shape ({X.shape[1]}, 2), got {b.shape}")
        diff = diff / (b[:, 1] - b[:, 0])
    return diff
