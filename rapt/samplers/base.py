"""The ask/tell contract every sampler follows.

Modelled on python-adaptive's learners: a sampler never runs the system under test.  It
proposes unit-cube points (``ask``) and is told what was evaluated (``tell``), so running,
parallelism, retries and persistence live in :mod:`rapt.search` alone.

Determinism: batch ``b`` of a sampler seeded with ``s`` draws its random numbers from
``SeedSequence([s, b])``, and every metamodel is rebuilt from the data told so far.  The
next batch is therefore a pure function of (seed, batch index, points asked, data), which is
what lets a killed study resume and produce exactly the study it would have produced
uninterrupted (tell the stored data, then :meth:`Sampler.fast_forward`).

The whole contract is in :class:`Sampler`'s docstring; ``tests/rapt/test_sampler_contract.py``
holds every sampler to it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np

from rapt.errors import InputError, RunError
from rapt.scores import check_output_types, infer_output_types

__all__ = ["Sampler"]


class Sampler(ABC):
    """Base class: data bookkeeping, seeding and validation shared by all samplers.

    The contract every sampler keeps:

    * ``ask(n)`` returns a new float array of ``m`` unit-cube points, shape ``(m, dim)``,
      ``0 <= m <= n``.  Samplers that never finish early (all of :data:`rapt.samplers.METHODS`)
      return exactly ``n``; one that may return fewer says so (a
      :class:`~rapt.manifold.ManifoldSampler` with ``whole_hulls`` counts ``n`` in labelled
      states, and its resolution cut-offs leave fewer candidates near the end).  Each ask
      that returns points is one batch: :attr:`n_batches` grows by 1 and :attr:`n_asked` by ``m``.
    * **Finishing early**: a sampler signals that it has nothing left worth asking by
      proposing no points.  :attr:`done` is then True and stays True; that ask and every
      later one return a ``(0, dim)`` array and count no batch, whatever is told afterwards.
      A caller loops ``while not sampler.done`` (or stops on an empty ask).
    * **Determinism**: the same seed, options and sequence of asks and tells give the same
      points; another seed gives other points.
    * ``tell(X, Y)`` records rows and proposes nothing (the ask counters do not move).  Rows
      accumulate: telling them in several calls is telling them at once, in the same order
      (but ``output_types``, when not given, are inferred from the first tell alone).
      Telling a row again counts it again (a system may evaluate one state twice, and that is
      data: a second neighbour in NNDV), so the state is not idempotent; what is guaranteed is
      that later asks stay valid, and that a sampler that is not :attr:`adaptive` asks exactly
      what it would have asked anyway: its asks depend on no score at all.
    * **Order of rows**: the next batch depends on the rows told, not on their order, with
      two exceptions: rows drawn into a seeded subsample by index once the data outgrow a cap
      (NNDV's ``max_reference``, GPR's ``max_fit`` and ``max_hyper_fit``, S-NDV's
      ``importance_samples``), and exact ties between distances (broken by row).  GPR refits a
      Gaussian process, whose rounding may differ in the last bits with the order.
    * **Resuming**: a fresh sampler told the same rows and fast-forwarded to the same
      counters (:meth:`fast_forward`) asks what the original would ask next.

    A subclass implements :meth:`_propose` (and may extend :meth:`tell`); the base class
    validates ``n``, seeds the batch, checks the shape, clips to the unit cube and keeps the
    counters and :attr:`done`.
    """

    #: Registry name used by :func:`rapt.search` (``method=``).
    name: str = ""
    #: Whether proposals depend on the scores told so far.
    adaptive: bool = False

    def __init__(self, dim: int, *, seed: int = 0, output_types: Sequence[str] | None = None):
        if not isinstance(dim, (int, np.integer)) or dim < 1:
            raise InputError(f"dim: expected a positive integer, got {dim!r}")
        if not isinstance(seed, (int, np.integer)) or seed < 0:
            raise InputError(f"seed: expected a non-negative integer, got {seed!r}")
        self.dim = int(dim)
        self.seed = int(seed)
        self.output_types = None if output_types is None else tuple(output_types)
        self.n_batches = 0  # asks so far (that returned points)
        self.n_asked = 0  # points proposed so far
        self.done = False  # finished early: no ask returns points again
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
        """Propose up to ``n`` unit-cube points, shape (m, dim) with m <= n; none once :attr:`done`."""
        if not isinstance(n, (int, np.integer)) or n < 1:
            raise InputError(f"n: expected a positive integer number of points, got {n!r}")
        if self.done:
            return np.empty((0, self.dim))
        rng = np.random.default_rng(np.random.SeedSequence([self.seed, self.n_batches]))
        points = np.asarray(self._propose(int(n), rng), dtype=float)
        if points.ndim != 2 or points.shape[1] != self.dim or points.shape[0] > n:
            raise RunError(f"{type(self).__name__} proposed shape {points.shape}, expected at most {(n, self.dim)}")
        if not len(points):
            self.done = True
            return np.empty((0, self.dim))
        self.n_batches += 1
        self.n_asked += len(points)
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
            raise InputError(f"X: expected shape (n, {self.dim}), got {X.shape}")
        if Y.ndim != 2 or Y.shape[0] != X.shape[0]:
            raise InputError(f"Y: expected one score row per state ({X.shape[0]}), got shape {Y.shape}")
        if not np.all(np.isfinite(Y)):
            raise InputError("Y: scores must be finite; report NaN/inf rows with tell_failed(X, reasons)")
        if not np.all(np.isfinite(X)):
            raise InputError("X: states must be finite")
        if X.shape[0] == 0:
            return
        if self.output_types is None:
            self.output_types = infer_output_types(Y)
        else:
            check_output_types(self.output_types, Y.shape[1])
        if self._Y and self._Y[0].shape[1] != Y.shape[1]:
            raise InputError(f"Y: expected {self._Y[0].shape[1]} score columns as before, got {Y.shape[1]}")
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
        """Return up to ``n`` proposals, (m, dim), or none to finish (:attr:`done`); ``rng`` is this batch's."""

    def __repr__(self) -> str:
        return f"{type(self).__name__}(dim={self.dim}, seed={self.seed}, told={self.n_told})"
