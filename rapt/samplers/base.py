"""The ask/tell contract every sampler follows.

Modelled on python-adaptive's learners: a sampler never runs the system under test.  It
proposes unit-cube points (``ask``) and is told what was evaluated (``tell``), so running,
parallelism, retries and persistence live in :mod:`rapt.search` alone.

Determinism: batch ``b`` of a sampler seeded with ``s`` draws its random numbers from
``SeedSequence([s, b])``, and every metamodel is rebuilt from the data told so far.  The
next batch is therefore a pure function of (seed, batch index, data), which is what lets a
killed study resume and produce exactly the study it would have produced uninterrupted.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Sequence

import numpy as np

from rapt.scores import check_output_types, infer_output_types

__all__ = ["Sampler"]


class Sampler(ABC):
    """Base class: data bookkeeping, seeding and validation shared by all samplers."""

    #: Registry name used by :func:`rapt.search` (``method=``).
    name: str = ""
    #: Whether proposals depend on the scores told so far.
    adaptive: bool = False

    def __init__(self, dim: int, *, seed: int = 0, output_types: Sequence[str] | None = None):
        if not isinstance(dim, (int, np.integer)) or dim < 1:
            raise ValueError(f"dim: expected a positive integer, got {dim!r}")
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
        self.dim = int(dim)
        self.seed = int(seed)
        self.output_types = None if output_types is None else tuple(output_types)
        self.n_batches = 0  # asks so far
        self.n_asked = 0  # points proposed so far
        self._X: list[np.ndarray] = []
        self._Y: list[np.ndarray] = []
        self._failed: list[np.ndarray] = []
        self._cache: tuple[np.ndarray, np.ndarray] | None = None

    # -- data -------------------------------------------------------------------------
    @property
    def X(self) -> np.ndarray:
        """Unit-cube states told so far (successful evaluations only), in tell order."""
        return self._data()[0]

    @property
    def Y(self) -> np.ndarray:
        """Scores told so far, one row per row of :attr:`X`."""
        return self._data()[1]

    @property
    def n_told(self) -> int:
        return int(sum(len(x) for x in self._X))

    @property
    def X_failed(self) -> np.ndarray:
        """States whose evaluation failed; kept out of every metamodel."""
        return np.concatenate(self._failed) if self._failed else np.empty((0, self.dim))

    def _data(self) -> tuple[np.ndarray, np.ndarray]:
        if self._cache is None:
            if self._X:
                self._cache = (np.concatenate(self._X), np.concatenate(self._Y))
            else:
                m = 0 if self.output_types is None else len(self.output_types)
                self._cache = (np.empty((0, self.dim)), np.empty((0, m)))
        return self._cache

    # -- contract ---------------------------------------------------------------------
    def ask(self, n: int) -> np.ndarray:
        """Propose ``n`` unit-cube points, shape (n, dim)."""
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise ValueError(f"n: expected a positive integer number of points, got {n!r}")
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.n_batches]))
        points = np.asarray(self._propose(int(n), rng), dtype=float)
        if points.shape != (n, self.dim):  # pragma: no cover - guards subclasses
            raise RuntimeError(f"{type(self).__name__} proposed shape {points.shape}, expected {(n, self.dim)}")
        self.n_batches += 1
        self.n_asked += int(n)
        return np.clip(points, 0.0, 1.0)

    def tell(self, X: np.ndarray, Y: np.ndarray) -> None:
        """Record evaluated states and their scores.

        ``X`` are the states actually evaluated, which may differ from those asked (a
        simulator may project a query onto a valid state).  Scores must be finite: report
        failed rows with :meth:`tell_failed` instead.
        """
        X = np.asarray(X, dtype=float)
        Y = np.asarray(Y, dtype=float)
        if Y.ndim == 1:
            Y = Y[:, None]
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise ValueError(f"X: expected shape (n, {self.dim}), got {X.shape}")
        if Y.ndim != 2 or Y.shape[0] != X.shape[0]:
            raise ValueError(f"Y: expected one score row per state ({X.shape[0]}), got shape {Y.shape}")
        if not np.all(np.isfinite(Y)):
            raise ValueError("Y: scores must be finite; report NaN/inf rows with tell_failed(X, reasons)")
        if not np.all(np.isfinite(X)):
            raise ValueError("X: states must be finite")
        if X.shape[0] == 0:
            return
        if self.output_types is None:
            self.output_types = infer_output_types(Y)
        else:
            check_output_types(self.output_types, Y.shape[1])
        if self._Y and self._Y[0].shape[1] != Y.shape[1]:
            raise ValueError(f"Y: expected {self._Y[0].shape[1]} score columns as before, got {Y.shape[1]}")
        self._X.append(X.copy())
        self._Y.append(Y.copy())
        self._cache = None

    def tell_failed(self, X: np.ndarray) -> None:
        """Record states whose evaluation failed (invalid scenario, crashed job)."""
        X = np.asarray(X, dtype=float).reshape(-1, self.dim)
        if X.shape[0]:
            self._failed.append(X.copy())

    def fast_forward(self, n_batches: int, n_asked: int) -> None:
        """Set the ask counters after replaying stored data, as if those batches had been asked here."""
        self.n_batches = int(n_batches)
        self.n_asked = int(n_asked)

    @abstractmethod
    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Return ``n`` proposals; ``rng`` is this batch's seeded generator."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dim={self.dim}, seed={self.seed}, told={self.n_told})"
