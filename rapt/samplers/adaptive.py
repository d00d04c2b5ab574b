"""Adaptive samplers that put the next batch where performance boundaries are likely.

All three follow Algorithm 1: rebuild a metamodel from every sample told so far, score
``p > L`` random candidates with an information metric, keep the best ``L`` without
near-duplicates.  They differ in the metamodel:

* :class:`GPRSampler` — Gaussian process, eq. 3.4 (O(n³): small studies only).
* :class:`NNDVSampler` — k-nearest-neighbour variance × distance, eq. 3.5 (O(k n log n)).
* :class:`ScaledNDVSampler` — S-NDV, eq. 3.8: NNDV per output in a space where each input
  is scaled by its tree importance for that output, averaged over outputs.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from rapt.candidates import CandidateGenerator, UniformCandidates, select_batch
from rapt.errors import InputError
from rapt.importance import importance_weights, tree_importance
from rapt.information import gpr_information, neighbour_variance, nndv_information, unalikeability
from rapt.parallel import query_workers
from rapt.samplers.base import Sampler
from rapt.samplers.space_filling import sobol_points
from rapt.scores import encode_labels, normalize_continuous

__all__ = ["InformationSampler", "NNDVSampler", "ScaledNDVSampler", "GPRSampler"]


def _check_positive(name: str, value: float, *, integer: bool = False, allow_zero: bool = False) -> None:
    ok = isinstance(value, (int, np.integer)) if integer else isinstance(value, (int, float, np.number))
    if not ok or not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        kind = "integer" if integer else "number"
        bound = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name}: expected a finite {kind} {bound}, got {value!r}")


class InformationSampler(Sampler):
    """Shared machinery: initial space-filling batch, candidates, selection.

    Parameters
    ----------
    g, v:
        Exponents on the boundary term (variance / gradient) and the exploration term
        (neighbour distance / predictive std).
    candidates_per_point, min_candidates:
        ``p = max(candidates_per_point · L, min_candidates)`` random candidates per batch.
    separation:
        Near-duplicate suppression inside a batch: a candidate within ``separation · d_K``
        of one already chosen is skipped (``d_K``: its mean distance to its neighbours).
    n_initial:
        Until this many samples have been told, batches come from a scrambled Sobol
        sequence (Algorithm 1's initial batch); the first batch always does.
    candidate_generator:
        Callable ``(n, rng, sampler) -> (n, d)``; uniform by default.
    """

    adaptive = True

    def __init__(
        self,
        dim: int,
        *,
        seed: int = 0,
        output_types: Sequence[str] | None = None,
        g: float = 1.0,
        v: float = 1.0,
        candidates_per_point: float = 10.0,
        min_candidates: int = 2000,
        separation: float = 0.5,
        n_initial: int = 0,
        candidate_generator: CandidateGenerator | None = None,
    ):
        super().__init__(dim, seed=seed, output_types=output_types)
        _check_positive("g", g, allow_zero=True)
        _check_positive("v", v, allow_zero=True)
        _check_positive("candidates_per_point", candidates_per_point)
        if candidates_per_point <= 1:
            raise InputError(f"candidates_per_point: must be > 1 (Algorithm 1 needs p > L), got {candidates_per_point}")
        _check_positive("min_candidates", min_candidates, integer=True, allow_zero=True)
        _check_positive("separation", separation, allow_zero=True)
        _check_positive("n_initial", n_initial, integer=True, allow_zero=True)
        if candidate_generator is not None and not callable(candidate_generator):
            raise InputError("candidate_generator: expected a callable (n, rng, sampler) -> (n, d) array")
        self.g = float(g)
        self.v = float(v)
        self.candidates_per_point = float(candidates_per_point)
        self.min_candidates = int(min_candidates)
        self.separation = float(separation)
        self.n_initial = int(n_initial)
        self.candidate_generator = candidate_generator or UniformCandidates()
        self.last_information: np.ndarray | None = None

    def _ready(self) -> bool:
        return self.n_told >= max(self.n_initial, self._min_data())

    def _min_data(self) -> int:
        return 2

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        if not self._ready():
            self.last_information = None
            return sobol_points(self.dim, self.seed, self.n_asked, n)
        p = max(int(np.ceil(self.candidates_per_point * n)), self.min_candidates, n + 1)
        cand = np.asarray(self.candidate_generator(p, rng, self), dtype=float)
        if cand.ndim != 2 or cand.shape[1] != self.dim or cand.shape[0] < n:
            raise InputError(
                f"candidate_generator: returned shape {cand.shape}; expected at least {n} rows of {self.dim} columns"
            )
        cand = np.clip(cand, 0.0, 1.0)
        info, space, radius = self.information(cand, rng)
        idx = select_batch(cand, info, n, self.separation * radius, space)
        self.last_information = info[idx]
        return cand[idx]

    def information(self, candidates: np.ndarray, rng: np.random.Generator):
        """Return (information per candidate, suppression-space coordinates, local length scale)."""
        raise NotImplementedError

    # Output encodings shared by the metamodels ----------------------------------------
    def _targets(self) -> list[tuple[str, np.ndarray, int]]:
        """Per output: (kind, codes or normalised values, n_classes or 0)."""
        Y = self.Y
        out = []
        for j, kind in enumerate(self.output_types or ()):  # set by the first tell, before any metamodel runs
            if kind == "continuous":
                out.append((kind, normalize_continuous(Y[:, j]), 0))
            else:
                codes, n_classes = encode_labels(Y[:, j])
                out.append((kind, codes, n_classes))
        return out


def _spread(kind: str, target: np.ndarray, n_classes: int, neighbours: np.ndarray) -> np.ndarray:
    """σ_K of eq. 3.5: unalikeability for labels, variance for continuous scores."""
    values = target[neighbours]
    if kind == "continuous":
        return neighbour_variance(values)
    return unalikeability(values, max(n_classes, 1))


class NNDVSampler(InformationSampler):
    """Nearest-Neighbour Density and Variance search (eq. 3.5), averaged over outputs.

    ``k`` neighbours; ``floor`` is added to the variance so that candidates in regions
    where all neighbours agree still compete on emptiness (exploration) rather than tie.
    ``max_reference`` caps the samples the neighbours come from (a seeded random subset
    per batch; see :meth:`_reference`): what keeps 10^5-sample studies in 10+ effective
    dimensions affordable.
    """

    name = "nndv"

    def __init__(self, dim: int, *, k: int = 8, floor: float = 0.02, max_reference: int | None = None, **kwargs):
        # g = 2 sharpens the variance term: measured better precision and coverage than
        # g = 1 on every synthetic system (benchmarks/search_quality.py).
        kwargs.setdefault("g", 2.0)
        super().__init__(dim, **kwargs)
        _check_positive("k", k, integer=True)
        if k < 2:
            raise InputError(f"k: need at least 2 neighbours for a variance, got {k}")
        _check_positive("floor", floor, allow_zero=True)
        self.k = int(k)
        self.floor = float(floor)
        if max_reference is not None:
            _check_positive("max_reference", max_reference, integer=True)
            if max_reference <= k:
                raise InputError(f"max_reference: must exceed k={k}, got {max_reference}")
        self.max_reference = None if max_reference is None else int(max_reference)

    def _min_data(self) -> int:
        return self.k + 1

    def _reference(self, rng: np.random.Generator) -> tuple[np.ndarray, list[tuple[str, np.ndarray, int]]]:
        """The samples the metric's neighbours come from, and their encoded outputs.

        All of them, or — past ``max_reference`` — a fresh seeded random subset per batch.
        Neighbour queries in many effective dimensions cost about O(n) each, so a study's
        asks grow as O(n²); the subset bounds that, and costs little resolution where it
        matters: the k-neighbour radius shrinks as n^(-1/d), only 11 % from 20k to 100k
        samples in 15 dimensions (but 2.2x in 2, so leave it off for small spaces).
        """
        X, targets = self.X, self._targets()
        if self.max_reference is None or X.shape[0] <= self.max_reference:
            return X, targets
        keep = np.sort(rng.choice(X.shape[0], self.max_reference, replace=False))
        return X[keep], [(kind, target[keep], n) for kind, target, n in targets]

    def information(self, candidates: np.ndarray, rng: np.random.Generator):
        X, targets = self._reference(rng)
        tree = cKDTree(X)
        dist, nbr = tree.query(candidates, k=self.k, workers=query_workers(len(candidates)))
        d_k = dist.mean(axis=1)
        info = np.zeros(candidates.shape[0])
        for kind, target, n_classes in targets:
            info += nndv_information(_spread(kind, target, n_classes, nbr), d_k, self.g, self.v, self.floor)
        return info / len(targets), candidates, d_k


class ScaledNDVSampler(NNDVSampler):
    """S-NDV (eq. 3.8): NNDV per output in importance-scaled space, averaged over outputs.

    For each output a CART tree on a bounded random subsample of the data gives the
    importance ``VI_i``; the space is ``X̄ ∘ w_i`` with ``w_i = VI_i / max VI_i``.  Batch
    near-duplicates are judged in the union space ``X̄ ∘ max_i w_i``.
    """

    name = "s-ndv"

    def __init__(self, dim: int, *, importance_samples: int = 20000, **kwargs):
        super().__init__(dim, **kwargs)
        _check_positive("importance_samples", importance_samples, integer=True)
        self.importance_samples = int(importance_samples)
        self.weights_: np.ndarray | None = None  # (m, d) from the latest ask

    def output_weights(self, rng: np.random.Generator) -> np.ndarray:
        X = self.X
        targets = self._targets()
        weights = np.empty((len(targets), self.dim))
        for i, (kind, target, _) in enumerate(targets):
            vi = tree_importance(
                X,
                target,
                "continuous" if kind == "continuous" else "categorical",
                max_samples=self.importance_samples,
                random_state=rng,
            )
            weights[i] = importance_weights(vi)
        return weights

    def information(self, candidates: np.ndarray, rng: np.random.Generator):
        weights = self.output_weights(rng)
        X, targets = self._reference(rng)
        self.weights_ = weights
        info = np.zeros(candidates.shape[0])
        d_k_first = None
        for (kind, target, n_classes), w in zip(targets, weights):
            tree = cKDTree(X * w)
            dist, nbr = tree.query(candidates * w, k=self.k, workers=query_workers(len(candidates)))
            d_k = dist.mean(axis=1)
            d_k_first = d_k if d_k_first is None else d_k_first
            info += nndv_information(_spread(kind, target, n_classes, nbr), d_k, self.g, self.v, self.floor)
        info /= len(targets)
        if len(targets) == 1:
            return info, candidates * weights[0], d_k_first
        union = weights.max(axis=0)
        dist, _ = cKDTree(X * union).query(candidates * union, k=self.k, workers=query_workers(len(candidates)))
        return info, candidates * union, dist.mean(axis=1)


class GPRSampler(InformationSampler):
    """Gaussian-process search (eq. 3.4): ``|∇μ|^g · σ^v`` with a Matérn covariance.

    The paper uses ν = d/2; it is snapped to the nearest of 0.5, 1.5 and 2.5, for which
    scikit-learn's kernel has closed-form gradients.  Categorical scores are one-hot
    encoded; the gradient is the Frobenius norm of the Jacobian of the predicted mean
    (central differences).  A GP is O(n³): it is fitted on at most ``max_fit`` samples (a
    seeded random subset) with kernel hyperparameters tuned on at most ``max_hyper_fit``,
    which keeps the method usable but is meant for small studies.
    """

    name = "gpr"

    def __init__(self, dim: int, *, max_fit: int = 1000, max_hyper_fit: int = 200, step: float = 1e-3, **kwargs):
        kwargs.setdefault("min_candidates", 1000)
        kwargs.setdefault("candidates_per_point", 5.0)
        super().__init__(dim, **kwargs)
        _check_positive("max_fit", max_fit, integer=True)
        _check_positive("max_hyper_fit", max_hyper_fit, integer=True)
        self.max_hyper_fit = int(max_hyper_fit)
        _check_positive("step", step)
        self.max_fit = int(max_fit)
        self.step = float(step)
        nu = dim / 2.0
        self.nu = min((0.5, 1.5, 2.5), key=lambda c: abs(c - nu))

    def _min_data(self) -> int:
        return 3

    def _design_targets(self) -> np.ndarray:
        cols = []
        for kind, target, n_classes in self._targets():
            if kind == "continuous":
                cols.append(target[:, None])
            elif n_classes <= 2:
                cols.append((target == (n_classes - 1)).astype(float)[:, None])
            else:
                cols.append(np.eye(n_classes)[target])
        return np.hstack(cols)

    def information(self, candidates: np.ndarray, rng: np.random.Generator):
        from sklearn.exceptions import ConvergenceWarning
        from sklearn.gaussian_process import GaussianProcessRegressor
        from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

        X = self.X
        T = self._design_targets()
        if X.shape[0] > self.max_fit:
            rows = np.sort(rng.choice(X.shape[0], size=self.max_fit, replace=False))
            X, T = X[rows], T[rows]
        kernel = ConstantKernel(1.0, (1e-3, 1e3)) * Matern(
            length_scale=0.2, length_scale_bounds=(1e-3, 10.0), nu=self.nu
        ) + WhiteKernel(1e-4, (1e-8, 1e-1))
        # Hyperparameters from a small subset (the optimiser's likelihood evaluations are the
        # O(n³) cost), then the posterior from all fitted samples with those fixed.
        hyper_rows = np.arange(X.shape[0])
        if X.shape[0] > self.max_hyper_fit:
            hyper_rows = np.sort(rng.choice(X.shape[0], size=self.max_hyper_fit, replace=False))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            tuned = GaussianProcessRegressor(kernel=kernel, normalize_y=True, random_state=int(rng.integers(2**31 - 1)))
            tuned.fit(X[hyper_rows], T[hyper_rows])
            gp = GaussianProcessRegressor(kernel=tuned.kernel_, normalize_y=True, optimizer=None)
            gp.fit(X, T)
        _, std = gp.predict(candidates, return_std=True)
        std = std.reshape(candidates.shape[0], -1).mean(axis=1)
        grad_sq = np.zeros(candidates.shape[0])
        h = self.step
        for j in range(self.dim):
            up = candidates.copy()
            dn = candidates.copy()
            up[:, j] = np.minimum(up[:, j] + h, 1.0)
            dn[:, j] = np.maximum(dn[:, j] - h, 0.0)
            width = (up[:, j] - dn[:, j])[:, None]
            diff = (gp.predict(up).reshape(len(up), -1) - gp.predict(dn).reshape(len(dn), -1)) / width
            grad_sq += (diff**2).sum(axis=1)
        info = gpr_information(np.sqrt(grad_sq), std, self.g, self.v)
        d_k, _ = cKDTree(self.X).query(candidates, k=1, workers=query_workers(len(candidates)))
        return info, candidates, d_k
