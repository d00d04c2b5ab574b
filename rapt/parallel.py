"""How many threads a k-d tree query should use.

``cKDTree.query(..., workers=-1)`` starts a thread per core on every call; for a few
thousand queries that start-up costs more than the queries themselves (a small
low-dimensional search makes many such calls), so small queries stay on the calling thread.
"""

from __future__ import annotations

#: Queries below this count run single-threaded.
PARALLEL_QUERY_THRESHOLD = 20_000


def query_workers(n_queries: int) -> int:
    """``workers=`` argument for a cKDTree query of ``n_queries`` points."""
    return -1 if n_queries >= PARALLEL_QUERY_THRESHOLD else 1
