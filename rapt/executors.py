"""Where simulations run: in process, in a process pool, or on a Dask cluster.

Anything that is a :class:`concurrent.futures.Executor` works.  A
``dask.distributed.Client`` is turned into ``client.get_executor(pure=False)`` — ``pure``
must be off, or Dask would cache repeated stochastic runs under one key.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
from typing import Any

from rapt.errors import InputError

__all__ = ["resolve_executor"]


def resolve_executor(executor: Any) -> tuple[cf.Executor | None, int]:
    """Return (executor or None for in-process calls, number of workers to size chunks for)."""
    if executor is None:
        return None, 1
    if hasattr(executor, "get_executor") and hasattr(executor, "ncores"):  # dask.distributed.Client
        workers = max(1, sum(executor.ncores().values()))
        return executor.get_executor(pure=False), workers
    if isinstance(executor, cf.Executor):
        workers = getattr(executor, "_max_workers", None) or os.cpu_count() or 1
        return executor, int(workers)
    raise InputError(
        f"executor: expected None, a concurrent.futures.Executor or a dask.distributed.Client, got {type(executor).__name__}"
    )
