"""What a running search has found so far: performance modes and boundary links.

The progress bar of ``rapt-plan generate`` shows, next to runs/s, how many performance
modes the search has met and how many boundary links it has made: new runs whose
nearest earlier run lies in another mode.  A link is the one-sided precursor of a
boundary pair (the pairs themselves are mutual nearest neighbours, found once the
search ends); counting links costs one nearest-neighbour query per batch against an
HNSW index grown as the runs arrive, where a k-d tree would have to be rebuilt for
every batch and, in the many dimensions of a mission's space, degrades to brute force.
"""

from __future__ import annotations

import numpy as np

__all__ = ["SearchStatus"]


class SearchStatus:
    """``on_batch`` callback of :func:`rapt.search` over the root scores (mission, safety)."""

    def __init__(self, dim: int):
        import faiss

        self._index = faiss.IndexHNSWFlat(int(dim), 16)
        self._index.hnsw.efSearch = 32
        self._modes: list[np.ndarray] = []
        self.mode_counts = np.zeros(4, dtype=np.int64)
        self.links = 0

    def __call__(self, U: np.ndarray, Y: np.ndarray) -> None:
        modes = (2 * Y[:, 0] + Y[:, 1]).astype(np.int64)
        U = np.ascontiguousarray(U, dtype=np.float32)
        if self._index.ntotal:
            _, nearest = self._index.search(U, 1)
            known = np.concatenate(self._modes)
            self.links += int(np.sum(known[nearest[:, 0]] != modes))
        self._index.add(U)
        self._modes.append(modes)
        self.mode_counts += np.bincount(modes, minlength=4)

    @property
    def modes_found(self) -> int:
        return int(np.count_nonzero(self.mode_counts))

    def summary(self) -> str:
        return f"{self.modes_found} modes, {self.links:,} boundary links"
