"""Space-filling designs: the baselines every adaptive search is measured against.

They ignore the scores they are told; ``ask`` depends only on (seed, points asked so far),
so a resumed study continues the same sequence.
"""

from __future__ import annotations

import warnings

import numpy as np
from scipy.stats import qmc

from rapt.errors import InputError
from rapt.samplers.base import Sampler

__all__ = ["RandomSampler", "SobolSampler", "LatinHypercubeSampler"]


class RandomSampler(Sampler):
    """Uniform random points (the "uniform random testing" baseline)."""

    name = "random"

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return rng.random((n, self.dim))


class SobolSampler(Sampler):
    """Scrambled Sobol sequence (scipy.stats.qmc), continued across batches."""

    name = "sobol"

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return sobol_points(self.dim, self.seed, self.n_asked, n)


def sobol_points(dim: int, seed: int, start: int, n: int) -> np.ndarray:
    """Points ``start .. start+n-1`` of the scrambled Sobol sequence seeded with ``seed``."""
    engine = qmc.Sobol(d=dim, scramble=True, seed=seed)
    if start:
        engine.fast_forward(start)
    with warnings.catch_warnings():
        # Balance properties need powers of two; batches rarely are, and the sequence is
        # still low-discrepancy as a whole.
        warnings.simplefilter("ignore", UserWarning)
        return engine.random(n)


class LatinHypercubeSampler(Sampler):
    """Latin hypercube design.

    With ``size`` (the study budget), one design of that size is drawn and served in
    slices, so the whole study is a Latin hypercube; past it, or without ``size``, each
    batch is its own Latin hypercube.
    """

    name = "lhs"

    def __init__(self, dim: int, *, seed: int = 0, size: int | None = None, output_types=None):
        super().__init__(dim, seed=seed, output_types=output_types)
        if size is not None and (not isinstance(size, (int, np.integer)) or size < 1):
            raise InputError(f"size: expected a positive integer or None, got {size!r}")
        self.size = None if size is None else int(size)
        self._design: np.ndarray | None = None

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        if self.size is not None and self.n_asked + n <= self.size:
            if self._design is None:
                self._design = qmc.LatinHypercube(d=self.dim, seed=np.random.default_rng([self.seed, 0xC0FFEE])).random(
                    self.size
                )
            return self._design[self.n_asked : self.n_asked + n]
        return qmc.LatinHypercube(d=self.dim, seed=rng).random(n)
