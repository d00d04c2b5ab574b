"""A maximum a posteriori fit of a few physical parameters, and what the data identify.

Fitting an execution bias or a vehicle model from a handful of field logs is a small
nonlinear least-squares problem whose data often say nothing about some parameters (one
tide phase cannot separate a tide-table error from a clock error).  A plain fit then
sends those parameters anywhere and a prediction built on them is worse than none.
:func:`fit_map` therefore gives every parameter a prior (:class:`Prior`: a centre, the
neutral or nominal value, and a width a test engineer would accept), minimises

    sum_i rho((r_i(theta) / s)^2) + sum_j ((theta_j - centre_j) / sd_j)^2

(``scipy.optimize.least_squares``, robust ``soft_l1`` loss against outliers, ``s`` the
data's own robust noise scale), and calls a parameter *identified* when its posterior
standard deviation is clearly below its prior's (:data:`IDENTIFIED_BELOW` of it).
An unidentified parameter is put back at its prior centre and the others are refitted
without it: prediction uses only what the data support.  Parameters the data confound
(one tide phase: a tide-table offset, a tide-table scale and a clock error all look the
same) are eliminated one at a time, the one whose fixing costs the fit least first; the
survivor then stands for the group and is kept only when the data need it (its estimate
:data:`SIGNIFICANT` s.e. off its centre), so noise is not attributed to a clock error.

Standard errors: the Laplace approximation ``(J^T J + I)^-1`` in prior-scaled units, the
cluster-robust (sandwich) estimate by ``groups`` when residuals within a group move
together (a segment of a track shares one unmodelled current), and, when asked, a block
bootstrap that resamples whole groups and refits, or a delete-one-group jackknife (with
few groups, the bootstrap's spread is optimistic; the jackknife's is not): the largest is
reported, since errors that are correlated across groups make the analytic ones optimistic.
Knows nothing of vehicles: the caller's ``residuals(theta)`` does the physics.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

__all__ = ["Prior", "MapEstimate", "fit_map", "IDENTIFIED_BELOW"]

#: A parameter is identified when its posterior s.d. is below this share of its prior s.d.
IDENTIFIED_BELOW = 0.5
#: A parameter identified only after its confounders were fixed must be this many s.e. off its centre.
SIGNIFICANT = 2.0
#: Function evaluations of a refit that starts at the estimate (an elimination candidate, a
#: bootstrap or jackknife replicate): a few Gauss-Newton steps from there are enough.
REFIT_NFEV = 20
#: Residuals beyond this many noise scales are down-weighted (``soft_l1``).
ROBUST_SCALE = 3.0


@dataclass(frozen=True)
class Prior:
    """A Gaussian prior on one parameter, truncated to ``[low, high]``."""

    name: str
    centre: float
    sd: float
    low: float = -math.inf
    high: float = math.inf

    def __post_init__(self):
        if not (self.sd > 0 and math.isfinite(self.sd)):
            raise ValueError(f"prior {self.name}: sd must be a positive number, got {self.sd}")
        if not self.low <= self.centre <= self.high:
            raise ValueError(f"prior {self.name}: centre {self.centre} is outside [{self.low}, {self.high}]")


@dataclass
class MapEstimate:
    """The fit: per parameter the value to predict with, the MAP value, a posterior s.d. and whether identified."""

    priors: tuple[Prior, ...]
    value: dict[str, float]  # identified: the MAP estimate; not identified: the prior centre
    map_value: dict[str, float]  # the MAP estimate with every parameter free
    stderr: dict[str, float]  # posterior standard deviation
    identified: dict[str, bool]
    noise_scale: dict  # robust scale of each kind of residual at the estimate, in the residuals' units
    residuals: int
    success: bool
    message: str
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)
    covariance: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # identified ones, in value units
    bootstrap: int = 0  # refits of the block bootstrap or jackknife (0: none)
    stderr_sources: dict[str, str] = field(default_factory=dict)  # which estimate gave each s.e.

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.priors)

    @property
    def identified_names(self) -> tuple[str, ...]:
        return tuple(n for n in self.names if self.identified[n])

    def vector(self) -> np.ndarray:
        return np.array([self.value[n] for n in self.names])

    def draws(self, k: int, seed: int = 0) -> np.ndarray:
        """``k`` posterior draws (rows in :attr:`names` order) of the identified parameters around
        :attr:`value`, the others at their centre; clipped to the priors' bounds."""
        rng = np.random.default_rng(seed)
        out = np.tile(self.vector(), (k, 1))
        idx = [i for i, n in enumerate(self.names) if self.identified[n]]
        if idx and k:
            cov = self.covariance
            z = rng.multivariate_normal(np.zeros(len(idx)), cov, size=k, method="eigh")
            out[:, idx] += z
        lo = np.array([p.low for p in self.priors])
        hi = np.array([p.high for p in self.priors])
        return np.clip(out, lo, hi)


def _robust_scale(r: np.ndarray) -> float:
    """1.4826 x median |r| (the normal s.d. for clean data), floored so a perfect fit is not singular."""
    if r.size == 0:
        return 1.0
    s = 1.4826 * float(np.median(np.abs(r)))
    rms = float(np.sqrt(np.mean(r**2)))
    return max(s, 1e-3 * rms, 1e-12)


#: How far inside its bounds (in prior s.d.) a parameter starts a fit.
START_MARGIN = 0.05


class _Problem:
    """The MAP fit as ``least_squares`` sees it: parameters in prior-scaled units ``z``, so the prior
    term is ``z`` itself and a parameter fixed at its centre is ``z = 0``."""

    def __init__(
        self,
        residuals: Callable[[np.ndarray], np.ndarray],
        priors: tuple[Prior, ...],
        residuals_many: Callable[[np.ndarray], np.ndarray] | None,
        max_nfev: int,
        diff_step: float,
        loss: str = "soft_l1",
    ):
        self.residuals, self.residuals_many = residuals, residuals_many
        self.max_nfev, self.diff_step, self.loss = max_nfev, diff_step, loss
        self.centre = np.array([p.centre for p in priors])
        self.sd = np.array([p.sd for p in priors])
        self.lo = (np.array([p.low for p in priors]) - self.centre) / self.sd
        self.hi = (np.array([p.high for p in priors]) - self.centre) / self.sd

    def theta(self, z: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Parameter values for ``z`` of the ``free`` ones, the others at their centre."""
        full = np.zeros(self.centre.size)
        full[free] = z
        return self.centre + self.sd * full

    def solve(
        self,
        free: np.ndarray,
        z0: np.ndarray,
        scale: np.ndarray | float,
        weight: np.ndarray | None = None,
        nfev: int | None = None,
    ):
        """Fit the ``free`` parameters from ``z0`` with residuals divided by ``scale`` (and weighted)."""
        lo, hi, diff_step = self.lo, self.hi, self.diff_step
        residuals, residuals_many, theta_of = self.residuals, self.residuals_many, self.theta
        w = None if weight is None else np.sqrt(weight)

        def fun(z: np.ndarray) -> np.ndarray:
            r = np.asarray(residuals(theta_of(z, free)), dtype=float) / scale
            if w is not None:
                r = r * w
            return np.concatenate([r, z])

        jac: object = "2-point"
        if residuals_many is not None:

            def jac(z: np.ndarray) -> np.ndarray:
                # forward differences, every step in one batched evaluation (backwards at an upper bound)
                k = z.size
                h = diff_step * np.maximum(1.0, np.abs(z))
                h = np.where(z + h > hi[free], -h, h)
                zs = np.vstack([z, z + np.diag(h)])
                R = np.asarray(residuals_many(np.array([theta_of(v, free) for v in zs])), dtype=float) / scale
                if w is not None:
                    R = R * w
                return np.vstack([((R[1:] - R[0]) / h[:, None]).T, np.eye(k)])

        # start well inside the bounds: from a point on (or 1e-9 off) a bound, trf's scaling shrinks
        # that coordinate's steps to nothing and the fit stops where it started (a prior centred on
        # its bound, e.g. a file value of 0 for a share in [0, 1])
        margin = np.minimum(START_MARGIN, (hi[free] - lo[free]) / 4)
        return least_squares(
            fun,
            np.clip(z0, lo[free] + margin, hi[free] - margin),
            bounds=(lo[free], hi[free]),
            method="trf",
            loss=self.loss,
            f_scale=ROBUST_SCALE,
            jac=jac,
            diff_step=diff_step,
            x_scale=1.0,
            max_nfev=self.max_nfev if nfev is None else nfev,
        )


def fit_map(
    residuals: Callable[[np.ndarray], np.ndarray],
    priors: Sequence[Prior],
    *,
    groups: np.ndarray | None = None,
    kinds: np.ndarray | None = None,
    bootstrap: int = 0,
    jackknife: bool = False,
    seed: int = 0,
    identify_below: float = IDENTIFIED_BELOW,
    significant: float = SIGNIFICANT,
    max_nfev: int = 200,
    diff_step: float = 1e-6,
    residuals_many: Callable[[np.ndarray], np.ndarray] | None = None,
    start: Mapping[str, float] | None = None,
    robust: bool = True,
    departed: bool = False,
) -> MapEstimate:
    """MAP estimate of ``priors``' parameters from ``residuals(theta) -> (m,)`` (see the module docstring).

    ``residuals`` takes parameter values in ``priors`` order and returns residuals in units
    of a nominal noise (their actual scale is estimated); its length must not depend on
    ``theta``.  ``groups`` (m,) labels residuals that share an error (a segment, a log):
    the robust and bootstrap standard errors treat each group as one draw.  ``kinds`` (m,)
    labels residuals of one kind (position, energy): each kind's noise scale is estimated
    on its own, so a precise kind is not drowned by a noisy one.  ``residuals_many(thetas)``
    (p, k) -> (p, m), when given, evaluates several parameter vectors at once: the
    Jacobian's finite differences then cost one batched call instead of k + 1.
    ``start`` (name -> value) starts the search there instead of at the prior centres: a good
    first guess from another measurement, for a fit whose robust loss flattens far from its
    optimum (the priors, and so the estimate, are unchanged).
    ``robust=False`` fits plain least squares with each kind's RMS as its noise scale: for data
    whose information lives in a few large residuals (a heading that only moves in turns), which
    the robust loss and median scale would treat as outliers.
    ``significant`` is the survivor rule's threshold (:data:`SIGNIFICANT`); 0 drops the rule,
    so that *identified* means exactly "posterior s.d. below ``identify_below`` of the prior's".
    ``departed=True`` also identifies a parameter whose s.d. is below ``identify_below`` of its move off
    the prior's centre (a far-off prior, another vehicle's datasheet, is no yardstick for such data).
    """
    priors = tuple(priors)
    names = [p.name for p in priors]
    problem = _Problem(residuals, priors, residuals_many, max_nfev, diff_step, "soft_l1" if robust else "linear")
    centre, sd, theta_of, solve = problem.centre, problem.sd, problem.theta, problem.solve

    r0 = np.asarray(residuals(centre), dtype=float)
    m = r0.size
    if groups is not None:
        groups = np.asarray(groups)
        if groups.shape != (m,):
            raise ValueError(f"groups: expected one label per residual ({m}), got shape {groups.shape}")

    every = np.ones(len(priors), dtype=bool)
    # the data's noise scale: from a fit with nominal units, then the MAP with the data's own scale
    kind = np.zeros(m, dtype=np.int64) if kinds is None else np.unique(np.asarray(kinds), return_inverse=True)[1]

    def scale_of(r: np.ndarray) -> float:
        return _robust_scale(r) if robust else max(float(np.sqrt(np.mean(r**2))) if r.size else 1.0, 1e-12)

    def scales(r: np.ndarray) -> np.ndarray:
        return np.array([scale_of(r[kind == k]) for k in range(int(kind.max(initial=0)) + 1)])[kind]

    z0 = np.array([((start or {}).get(p.name, p.centre) - p.centre) / p.sd for p in priors])
    first = solve(every, z0, 1.0)
    scale = scales(first.fun[:m])
    sol = solve(every, first.x, scale)
    scale = scales(sol.fun[:m] * scale)
    sol = solve(every, sol.x, scale)
    map_value = theta_of(sol.x, every)
    stderr_z = np.ones(len(priors))
    limit = functools.partial(_identified_below, share=identify_below, departed=departed)
    own = _covariances(sol, m, groups)[0] < limit(sol.x)  # identified with every parameter free
    sources = {n: "laplace" for n in names}
    free = every.copy()
    final, cov_f, n_boot = sol, np.zeros((0, 0)), 0
    # backward elimination: while one is not identified, fix the cheapest at its centre (_drop_one), refit
    while free.any():
        if not free.all():
            final = solve(free, sol.x[free], scale)
        sd_f, cov_f, source = _covariances(final, m, groups)
        below = limit(final.x)
        if np.all(sd_f < below) and (bootstrap > 0 or jackknife) and groups is not None:
            sd_f, cov_f, source, n_boot = _resampled(
                solve, free, final.x, scale, groups, sd_f, cov_f, source, bootstrap, jackknife, seed
            )
        stderr_z[free] = sd_f
        for n, src in zip([n for n, f in zip(names, free) if f], source):
            sources[n] = src
        if np.any(sd_f >= below):
            free = _drop_one(solve, free, sol.x, scale, np.flatnonzero(free)[sd_f >= below])
            continue
        # a parameter identified only once its confounders were fixed stands for all of them:
        # keep it only if the data need it (its estimate significantly off its centre)
        idx = np.flatnonzero(free)
        z = np.abs(final.x) / np.maximum(sd_f, 1e-300)
        weak = [i for i in range(idx.size) if not own[idx[i]] and z[i] < significant]
        if not weak:
            break
        free[idx[min(weak, key=lambda i: z[i])]] = False
    for n, f in zip(names, free):
        if not f:
            sources[n] = "not identified"
    corr, cov_value = _correlations(cov_f, sd, names, free)
    value = theta_of(final.x, free) if free.any() else centre.copy()
    res = np.asarray(residuals(value), dtype=float)
    return MapEstimate(
        priors,
        {n: float(v) for n, v in zip(names, value)},
        {n: float(v) for n, v in zip(names, map_value)},
        {n: float(v * s) for n, v, s in zip(names, stderr_z, sd)},
        {n: bool(f) for n, f in zip(names, free)},
        {str(k): scale_of(res[kind == i]) for i, k in enumerate(np.unique(kinds) if kinds is not None else [0])},
        int(m),
        bool(final.success),
        str(final.message),
        corr,
        cov_value,
        n_boot,
        sources,
    )


def _identified_below(z: np.ndarray, share: float, departed: bool) -> np.ndarray:
    """The s.d. (prior units) below which each parameter at ``z`` is identified (see :func:`fit_map`)."""
    return share * (np.maximum(1.0, np.abs(z)) if departed else np.ones(z.size))


def _resampled(
    solve,
    free: np.ndarray,
    z: np.ndarray,
    scale: np.ndarray | float,
    groups: np.ndarray,
    sd_f: np.ndarray,
    cov_f: np.ndarray,
    source: list[str],
    bootstrap: int,
    jackknife: bool,
    seed: int,
) -> tuple[np.ndarray, np.ndarray, list[str], int]:
    """The s.d. ``sd_f`` (with covariance and sources) widened where the jackknife or block bootstrap
    around the estimate ``z`` is wider, and the number of refits that took."""
    if jackknife:
        sd_b, n_boot, how = _jackknife(solve, free, z, scale, groups), np.unique(groups).size, "jackknife"
    else:
        boot = _bootstrap(solve, free, z, scale, groups, bootstrap, seed)
        n_boot, how = boot.shape[0], "bootstrap"
        sd_b = boot.std(axis=0, ddof=1) if n_boot > 1 else np.zeros(sd_f.size)
    if n_boot > 1:
        for i in range(sd_f.size):
            if sd_b[i] > sd_f[i]:
                sd_f[i], source[i] = sd_b[i], how
        d = np.sqrt(np.clip(np.diag(cov_f), 1e-300, None))
        cov_f = cov_f / np.outer(d, d) * np.outer(sd_f, sd_f)  # the correlations, at the chosen widths
    return sd_f, cov_f, source, n_boot


def _correlations(
    cov_f: np.ndarray, sd: np.ndarray, names: list[str], free: np.ndarray
) -> tuple[dict[str, dict[str, float]], np.ndarray]:
    """The identified parameters' correlations by name, and their covariance in value units
    (``cov_f`` is in prior-scaled units)."""
    corr: dict[str, dict[str, float]] = {}
    cov_value = np.zeros((int(free.sum()), int(free.sum())))
    if free.any():
        cov_value = cov_f * np.outer(sd[free], sd[free])
        d = np.sqrt(np.clip(np.diag(cov_f), 1e-300, None))
        c = cov_f / np.outer(d, d)
        kn = [n for n, f in zip(names, free) if f]
        corr = {a: {b: float(c[i, j]) for j, b in enumerate(kn) if b != a} for i, a in enumerate(kn)}
    return corr, cov_value


def _drop_one(solve, free: np.ndarray, z: np.ndarray, scale, candidates: np.ndarray) -> np.ndarray:
    """``free`` without the candidate whose fixing at its centre costs the fit least: of parameters
    the data confound, the one they explain least goes (likelihood-ratio backward elimination)."""
    best, best_cost = free, np.inf
    for c in candidates.tolist():
        trial = free.copy()
        trial[c] = False
        cost = solve(trial, z[trial], scale, nfev=REFIT_NFEV).cost if trial.any() else -1.0
        if cost < best_cost:
            best, best_cost = trial, cost
    return best


def _covariances(sol, m: int, groups: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Posterior s.d. (prior-scaled units) of the solution's free parameters: the larger of the
    Laplace and the cluster-robust estimate; with the covariance and which one won, per parameter."""
    J = sol.jac[:m]  # data rows, already divided by the noise scale
    k = J.shape[1]
    # (J^T J + I)^-1 from the SVD of [J; I]: its singular values are >= 1 (the prior), so a
    # direction the data do not see keeps its prior width however precise the rest is
    _, sv, vt = np.linalg.svd(np.vstack([J, np.eye(k)]), full_matrices=False)
    bread = (vt.T / sv**2) @ vt
    sd = np.sqrt(np.clip(np.diag(bread), 0, None))
    cov = bread.copy()
    source = ["laplace"] * k
    if groups is not None and m:
        res = sol.fun[:m]
        _, g = np.unique(groups, return_inverse=True)
        score = np.zeros((int(g.max()) + 1, k))
        np.add.at(score, g, J * res[:, None])
        robust = bread @ (score.T @ score + np.eye(k)) @ bread
        rsd = np.sqrt(np.clip(np.diag(robust), 0, None))
        for i in range(k):
            if rsd[i] > sd[i]:
                sd[i], source[i] = rsd[i], "cluster-robust"
        if np.any(rsd > np.sqrt(np.clip(np.diag(bread), 0, None))):
            cov = robust
    return sd, cov, source


def _jackknife(solve, free: np.ndarray, z: np.ndarray, scale: np.ndarray | float, groups: np.ndarray) -> np.ndarray:
    """Delete-one-group jackknife s.d. (prior units) of the free parameters: each group left out once, refitted."""
    labels, g = np.unique(groups, return_inverse=True)
    if labels.size < 3:
        return np.zeros(int(free.sum()))
    out = np.array(
        [solve(free, z, scale, weight=(g != j).astype(float), nfev=REFIT_NFEV).x for j in range(labels.size)]
    )
    n = labels.size
    return np.sqrt((n - 1) / n * np.sum((out - out.mean(axis=0)) ** 2, axis=0))


def _bootstrap(
    solve, free: np.ndarray, z: np.ndarray, scale: np.ndarray | float, groups: np.ndarray, b: int, seed: int
) -> np.ndarray:
    """Refits on ``b`` resamples of whole groups (with replacement, seeded): (draws, free) in prior units."""
    labels, g = np.unique(groups, return_inverse=True)
    if labels.size < 3:
        return np.zeros((0, int(free.sum())))
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(b):
        counts = np.bincount(rng.integers(0, labels.size, labels.size), minlength=labels.size)
        sol = solve(free, z, scale, weight=counts[g].astype(float), nfev=REFIT_NFEV)
        out.append(sol.x)
    return np.array(out)
