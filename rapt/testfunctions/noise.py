"""Noisy systems: fuzzy boundaries and global label errors (sections 4.2.1-4.2.2).

Each wraps a base system, draws from one seeded Generator in call order, and keeps the
base's exact ``boundary_distance``: the noise blurs the labels, not where the boundary is.
"""

from __future__ import annotations

import numpy as np

from rapt.errors import InputError
from rapt.testfunctions.base import CATEGORICAL, SyntheticSystem

__all__ = ["FuzzyBoundary", "GlobalNoise"]


class _NoiseWrapper(SyntheticSystem):
    """Shared plumbing of the stochastic wrappers: one Generator, seeded once."""

    def __init__(self, base: SyntheticSystem, seed, suffix: str):
        self.base = base
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.name = f"{base.name}-{suffix}"
        self.dim = base.dim
        self.n_outputs = base.n_outputs
        self.output_types = tuple(base.output_types)
        self.n_classes = tuple(base.n_classes)
        self.active_dims = tuple(base.active_dims)
        self._cat = [i for i, t in enumerate(self.output_types) if t == CATEGORICAL]

    def reset(self, seed=None) -> None:
        """Restart the random stream from ``seed`` (default: the constructor's seed).

        Only an integer or SeedSequence seed restarts the stream; a Generator passed as
        seed is reused as is, continuing where it is.
        """
        self.rng = np.random.default_rng(self.seed if seed is None else seed)

    def _distance(self, X):
        return self.base.boundary_distance(X)


class FuzzyBoundary(_NoiseWrapper):
    """Fuzzy boundaries (section 4.2.1): labels drawn at a Gaussian-jittered input.

    Every categorical output is evaluated at ``clip(x + N(0, sigma^2 I), 0, 1)``, the noise
    being added to the active input columns of the categorical outputs (one independent
    draw per column).  Near a (locally straight) boundary the label flips with
    probability ``Phi(-d / sigma)``, a Gaussian tail in the distance ``d``, so the
    boundary becomes a band of width ~``sigma`` where either mode can occur.  Continuous
    outputs are returned noise-free.  ``boundary_distance`` is the base's.
    Calls are deterministic given ``seed`` and the call order.
    """

    def __init__(self, base: SyntheticSystem, sigma: float, seed=0):
        if not (np.isfinite(sigma) and sigma >= 0):
            raise InputError(f"sigma must be a finite number >= 0, got {sigma!r}")
        super().__init__(base, seed, f"fuzzy{sigma:g}")
        self.sigma = float(sigma)
        self._jitter_dims = sorted({a for i in self._cat for a in base.active_dims[i]})

    def _evaluate(self, X):
        if not self._cat or not self._jitter_dims:
            return self.base(X)
        cols = self._jitter_dims
        Z = X.copy()
        noise = self.rng.normal(0.0, self.sigma, size=(X.shape[0], len(cols)))
        Z[:, cols] = np.clip(Z[:, cols] + noise, 0.0, 1.0)
        Y = self.base(Z)
        if len(self._cat) < self.n_outputs:
            clean = self.base(X)
            cont = [i for i in range(self.n_outputs) if i not in self._cat]
            Y[:, cont] = clean[:, cont]
        return Y


class GlobalNoise(_NoiseWrapper):
    """Global error (section 4.2.2): labels replaced by a wrong mode with probability ``rate``.

    Independently for every sample and categorical output, with probability ``rate`` the
    label ``c`` becomes ``(c + k) mod C`` with ``k`` uniform in ``1..C-1``, i.e. a
    uniformly chosen *different* class.  Continuous outputs are untouched;
    ``boundary_distance`` is the base's.  Deterministic given ``seed`` and call order.
    """

    def __init__(self, base: SyntheticSystem, rate: float, seed=0):
        if not (0.0 <= rate <= 1.0):
            raise InputError(f"rate must be in [0, 1], got {rate!r}")
        super().__init__(base, seed, f"noise{rate:g}")
        self.rate = float(rate)

    def _evaluate(self, X):
        Y = self.base(X)
        n = X.shape[0]
        for i in self._cat:
            C = self.n_classes[i]
            flip = self.rng.random(n) < self.rate
            shift = self.rng.integers(1, C, size=n) if C > 1 else np.zeros(n, dtype=int)
            Y[:, i] = np.where(flip, (Y[:, i] + shift) % C, Y[:, i])
        return Y
