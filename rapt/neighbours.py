"""A k-nearest-neighbour graph grown batch by batch while a search runs.

The sub-boundary tree (:func:`rapt.subboundary_tree`) pairs samples through one k-nearest
neighbour graph of the whole study.  Built from scratch once the search ends, that graph
costs more than the rest of the analysis together (minutes for 10^6 samples in 18
dimensions).  A search produces its samples in batches anyway, so :class:`GrowingGraph`
links each batch in as it arrives: the analysis finds the graph ready, and the cost is
spread over the search, a small share of each batch.

Each node keeps its ``k`` nearest known neighbours, nearest first.  A new batch is joined
to the graph in two directions: each new row gets its nearest rows among everything so far,
and each row, old or new, whose list a new row improves takes it in.

* Up to ``exact_max`` rows (:data:`rapt.boundaries.EXACT_GRAPH_MAX_SAMPLES`) the distances
  are computed by brute force, each batch against all rows, and the graph is the exact
  k-nearest-neighbour graph (ties at float32 resolution broken by the lower row index).
* Beyond, the rows go into a faiss HNSW index and each new row is searched in it; every
  edge found serves both its ends, so the graph's recall is at least that of
  :func:`rapt.boundaries.knn_graph` built from scratch (``benchmarks/boundaries.py``).

The graph depends only on the rows and their batches: the HNSW index is always filled
batch by batch in the same chunks (on a single OpenMP thread, since faiss's parallel
insertion depends on thread timing), so a study resumed from its store grows the same
graph as one run without a stop.  Lists change in place, so the store keeps each node's
current list (:meth:`rapt.store.StudyStore.put_neighbours`), written per batch for the
nodes that changed.

Memory: ids are int32 and distances float32, 96 bytes per node at ``k = 12``, plus the HNSW
index (about 200 bytes per 18-D node), which is what lets the graph grow to 10^6 rows.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rapt.boundaries import EXACT_GRAPH_MAX_SAMPLES, HNSW_EF_CONSTRUCTION, HNSW_M
from rapt.errors import FileFormatError, InputError

__all__ = ["GrowingGraph"]

#: Rows of a batch compared at once in the exact regime (bounds the distance block's memory).
_EXACT_CHUNK = 128
#: Each new row is searched for ``3 k`` neighbours (candidate list ``GROW_EF_SEARCH``), not
#: ``k``: the extra ones are offered the new row in return, which is how an old row learns of
#: a nearer newcomer.  With ``k`` only, recall of the exact 12 nearest falls to about 82 %
#: (10^5 uniform rows in 18-D, batches of 2,500), with ``3 k`` it is about 94 %, above the
#: graph built from scratch (93 %), for about 1.3x the search time.
GROW_CANDIDATES = 3
GROW_EF_SEARCH = 48


class GrowingGraph:
    """Each row's ``k`` nearest other rows, kept up to date as batches of rows are added.

    ``exact_max`` (default :data:`EXACT_GRAPH_MAX_SAMPLES`): while the graph holds no more
    rows, it is exact; beyond, batches are linked through an HNSW index.

    ``add(U)`` links a batch in and returns the nodes whose lists changed; ``graph()``
    returns ``(dist, idx)``, both (N, k), nearest first, aligned with the rows in the order
    they were added.  A node with fewer than ``k`` other rows pads its list with its own
    index at infinite distance, which no pairing uses.
    """

    def __init__(self, dim: int, k: int = 12, exact_max: int | None = None):
        if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k < 1:
            raise InputError(f"neighbour_graph: expected a positive number of neighbours k, got {k!r}")
        self.dim = int(dim)
        self.k = int(k)
        self.exact_max = int(EXACT_GRAPH_MAX_SAMPLES if exact_max is None else exact_max)
        self.n = 0
        self.batch_sizes: list[int] = []
        self._idx = np.full((0, self.k), -1, dtype=np.int32)
        self._dist = np.full((0, self.k), np.inf, dtype=np.float32)
        self._rows: list[np.ndarray] | None = []  # the rows themselves, kept while the graph is exact
        self._index: Any = None  # faiss HNSW index, created when the graph outgrows exact_max
        self._restored = 0  # rows whose lists came from a store and that extend() must still take in

    # -- growing ---------------------------------------------------------------------------
    def add(self, U: np.ndarray) -> np.ndarray:
        """Link a batch of rows (B, dim) into the graph; returns the nodes whose lists changed."""
        U = self._check(U)
        n0, n1 = self.n, self.n + U.shape[0]
        self._reserve(n1)
        self.batch_sizes.append(U.shape[0])
        self.n = n1
        if U.shape[0] == 0:
            return np.empty(0, dtype=np.int64)
        if n1 <= self.exact_max:
            assert self._rows is not None
            self._rows.append(U)
            return self._link_exact(U, n0)
        self._index_add(U)
        return self._link_hnsw(U, n0)

    def extend(self, U: np.ndarray) -> None:
        """Take in a batch whose lists were restored from a store: the rows, without linking them."""
        U = self._check(U)
        if self.n + U.shape[0] > self._restored:
            raise FileFormatError(
                "store: the stored neighbour graph holds fewer rows than its batches; "
                "delete its neighbours table to rebuild it"
            )
        self.batch_sizes.append(U.shape[0])
        self.n += U.shape[0]
        if U.shape[0] == 0:
            return
        if self.n <= self.exact_max:
            assert self._rows is not None
            self._rows.append(U)
        else:
            self._index_add(U)

    def restore(self, idx: np.ndarray, dist: np.ndarray) -> None:
        """Load stored lists (N, k) of nodes 0..N-1; their rows follow through :meth:`extend`."""
        if self.n:
            raise InputError("neighbour_graph: restore a stored graph before adding rows")
        idx = np.asarray(idx, dtype=np.int32).reshape(-1, self.k)
        self._reserve(idx.shape[0])
        self._idx[: idx.shape[0]] = idx
        self._dist[: idx.shape[0]] = np.asarray(dist, dtype=np.float32).reshape(-1, self.k)
        self._restored = idx.shape[0]

    # -- reading ---------------------------------------------------------------------------
    def lists(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Stored form of some nodes' lists: (idx int32, dist float32), -1 / inf where empty."""
        return self._idx[nodes], self._dist[nodes]

    def graph(self) -> tuple[np.ndarray, np.ndarray]:
        """``(dist, idx)``: (N, k) float32 distances and int32 indices, nearest first."""
        idx = self._idx[: self.n].copy()
        dist = self._dist[: self.n].copy()
        empty = idx < 0
        if empty.any():
            idx[empty] = np.broadcast_to(np.arange(self.n, dtype=np.int32)[:, None], idx.shape)[empty]
        return dist, idx

    # -- internals -------------------------------------------------------------------------
    def _check(self, U: np.ndarray) -> np.ndarray:
        U = np.asarray(U, dtype=float)
        if U.ndim != 2 or U.shape[1] != self.dim:
            raise InputError(f"U: expected rows of {self.dim} inputs, got shape {U.shape}")
        return U

    def _reserve(self, n: int) -> None:
        if n <= self._idx.shape[0]:
            return
        size = max(n, 2 * self._idx.shape[0], 1024)
        idx = np.full((size, self.k), -1, dtype=np.int32)
        dist = np.full((size, self.k), np.inf, dtype=np.float32)
        idx[: self._idx.shape[0]] = self._idx
        dist[: self._dist.shape[0]] = self._dist
        self._idx, self._dist = idx, dist

    def _link_exact(self, U: np.ndarray, n0: int) -> np.ndarray:
        """Brute force, one distance block per chunk of new rows against all rows.

        A new row's k nearest come from its block row; an old row takes in the new rows
        nearer than its current k-th neighbour (it already holds its k nearest old rows),
        so every list is exact after the batch.
        """
        assert self._rows is not None
        rows = np.vstack(self._rows)
        n1 = rows.shape[0]
        sq_rows = np.einsum("ij,ij->i", rows, rows)
        kth = self._dist[:n0, -1].astype(float) ** 2  # inf while a list is not full
        kk = min(self.k, n1 - 1)
        src, dst, dd = [], [], []
        for s in range(0, U.shape[0], _EXACT_CHUNK):
            D = rows[n0 + s : n0 + s + _EXACT_CHUNK] @ rows.T
            D *= -2.0
            D += sq_rows[n0 + s : n0 + s + D.shape[0], None]
            D += sq_rows[None, :]
            np.maximum(D, 0.0, out=D)  # rounding: about 1e-15 of |x|^2, far below float32
            own = np.arange(D.shape[0])
            D[own, n0 + s + own] = np.inf
            new = n0 + s + own
            if kk > 0:  # each new row's k nearest of all rows
                near = _smallest(D, kk)
                src.append(np.repeat(new, kk))
                dst.append(near.ravel())
                dd.append(np.take_along_axis(D, near, axis=1).ravel())
            r, c = np.nonzero(D[:, :n0] <= kth[None, :])  # old rows offered a nearer new row
            src.append(c)
            dst.append(new[r])
            dd.append(D[r, c])
        if not src:
            return np.empty(0, dtype=np.int64)
        d = np.sqrt(np.concatenate(dd)).astype(np.float32)
        return self._merge(np.concatenate(src), np.concatenate(dst), d)

    def _link_hnsw(self, U: np.ndarray, n0: int) -> np.ndarray:
        """Search the new rows in the HNSW index (which holds them); each edge serves both ends."""
        import faiss

        assert self._index is not None
        Uf = np.ascontiguousarray(U, dtype=np.float32)
        b, kq = Uf.shape[0], GROW_CANDIDATES * self.k + 1  # the row itself comes back too
        params = faiss.SearchParametersHNSW()  # type: ignore[attr-defined]
        params.efSearch = max(GROW_EF_SEARCH, kq)
        sq = np.empty((b, kq), dtype=np.float32)
        found = np.empty((b, kq), dtype=np.int64)
        entry = np.arange(n0, n0 + b, dtype=np.int32)  # start each search at the row itself
        entry_d = np.zeros(b, dtype=np.float32)
        self._index.search_level_0(
            b,
            faiss.swig_ptr(Uf),
            kq,
            faiss.swig_ptr(entry),
            faiss.swig_ptr(entry_d),
            faiss.swig_ptr(sq),
            faiss.swig_ptr(found),
            1,
            1,
            params,
        )
        new = np.repeat(np.arange(n0, n0 + b), kq)
        found_f = found.ravel()
        ok = (found_f >= 0) & (found_f != new)
        new, found_f = new[ok], found_f[ok]
        d = np.sqrt(np.maximum(sq.ravel()[ok], 0.0)).astype(np.float32)
        return self._merge(np.concatenate([new, found_f]), np.concatenate([found_f, new]), np.concatenate([d, d]))

    def _index_add(self, U: np.ndarray) -> None:
        """Add rows to the HNSW index, creating it (from the earlier rows, batch by batch) the first time."""
        import faiss

        if self._index is None:
            self._index = faiss.IndexHNSWFlat(self.dim, HNSW_M)
            self._index.hnsw.efConstruction = HNSW_EF_CONSTRUCTION
            for rows in self._rows or []:
                self._index_add(rows)
            self._rows = None
        threads = faiss.omp_get_max_threads()
        faiss.omp_set_num_threads(1)  # parallel insertion is not deterministic
        try:
            self._index.add(np.ascontiguousarray(U, dtype=np.float32))
        finally:
            faiss.omp_set_num_threads(threads)

    def _merge(self, src: np.ndarray, dst: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Offer ``dst`` to ``src`` as a neighbour at distance ``d``; keep each list's k nearest.

        Lists are ordered by (distance, index), so they depend only on the offers made, not
        on their order.  The offers to a node are inserted in rounds, at most ``k``, one per
        node and round, each round vectorised over the nodes.  Returns the nodes whose
        lists changed.
        """
        d = np.asarray(d, dtype=np.float32)
        last, kth = self._idx[src, -1], self._dist[src, -1]
        # An offer no nearer than a full list's k-th neighbour cannot enter it.
        keep = np.isfinite(d) & ((d < kth) | ((d == kth) & (dst < last)) | (last < 0))
        src, key = src[keep], _order_key(d[keep], dst[keep])
        if not src.size:
            return np.empty(0, dtype=np.int64)
        order = np.lexsort((key, src))  # by node, nearest offer first
        src, key = src[order], key[order]
        fresh = np.r_[True, (src[1:] != src[:-1]) | (key[1:] != key[:-1])]  # an edge offered from both ends
        src, key = src[fresh], key[fresh]
        starts = np.flatnonzero(np.r_[True, src[1:] != src[:-1]])
        counts = np.diff(np.r_[starts, src.size])
        nodes = src[starts]
        before = self._idx[nodes].copy()
        cols = np.arange(self.k)
        for r in range(min(int(counts.max()), self.k)):  # later offers lose to the k earlier ones
            at = starts[counts > r] + r
            nd, offer = src[at], key[at]
            K = _order_key(self._dist[nd], self._idx[nd])
            pos = np.sum(K < offer[:, None], axis=1)
            enter = (pos < self.k) & ~np.any(K == offer[:, None], axis=1)
            nd, offer, pos, K = nd[enter], offer[enter], pos[enter], K[enter]
            shifted = np.empty_like(K)
            shifted[:, 0] = offer
            shifted[:, 1:] = K[:, :-1]
            P = pos[:, None]
            K = np.where(cols < P, K, np.where(cols == P, offer[:, None], shifted))
            self._dist[nd] = (K >> 32).astype(np.uint32).view(np.float32)
            self._idx[nd] = (K & 0xFFFFFFFF).astype(np.uint32).view(np.int32)
        changed = np.any(self._idx[nodes] != before, axis=1)
        return nodes[changed]


def _order_key(d: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """One int64 per (distance, index) that sorts as the pair: a non-negative float32's bits
    order like the float, and the index breaks ties (an empty slot, -1 at inf, sorts last)."""
    bits = np.asarray(d, dtype=np.float32).view(np.uint32).astype(np.int64)
    return (bits << 32) | (np.asarray(idx).astype(np.int64) & 0xFFFFFFFF)


def _smallest(D: np.ndarray, k: int) -> np.ndarray:
    """Column indices of each row's ``k`` smallest entries (any order)."""
    if k >= D.shape[1]:
        return np.broadcast_to(np.arange(D.shape[1]), D.shape).copy()
    return np.argpartition(D, k - 1, axis=1)[:, :k]
