"""LOLA-Voronoi (Crombecq, Gorissen, Deschrijver, Dhaene 2011): the dissertation's peer in Table 3.1.

A hybrid sequential design for *global surrogate modelling*: it ranks every sample's
Voronoi cell by

* **exploration** ``V(p)``: the cell's volume, estimated by Monte Carlo (uniform test
  points, each assigned to its nearest sample);
* **exploitation** ``E(p)``: LOLA's local nonlinearity.  Each sample ``p`` gets a
  neighbourhood of ``m = 2d`` samples that maximises the neighbourhood score
  ``S = R / C`` (cohesion ``C``: mean distance of the neighbours to ``p``; adhesion
  ``A``: mean distance of each neighbour to its nearest fellow neighbour; cross-polytope
  ratio ``R = A / (sqrt(2) C)``, or the paper's 1-D formula), a gradient ``g`` fitted to
  the neighbours by least squares, and ``E(p) = sum_j |f(p_j) - f(p) - g . (p_j - p)|``,

and combines them as ``H(p) = V(p) + E(p) / sum E`` (both terms sum to 1).  Each new
point goes into one of the highest-ranked cells: the Monte Carlo point of that cell
farthest from every sample (and from the points already chosen in this batch).

Outputs: a categorical (or binary) output becomes one indicator per class (one vs rest),
whose nonlinearities are summed; a continuous output is used as it is.  Each output's
nonlinearity is normalised to sum 1 and the outputs are averaged.

Differences from SUMO's MATLAB code, all for cost or determinism: neighbourhoods are
rebuilt from scratch each batch (the next batch is a pure function of the data, see
:mod:`rapt.samplers.base`), choosing greedily among each sample's ``3m`` nearest samples
(closest first; a candidate replaces the member whose swap raises ``S`` most) instead of
updating them incrementally over all samples; duplicate states are merged (their
indicator / score rows averaged).

Cost per batch with ``N`` samples, ``k = 3m`` neighbour candidates and ``T`` Monte Carlo
points (``100 N``, capped at ``max_test_points``): k-d tree queries
O((N k + T) log N), neighbourhood search O(N k^2 d) for the distances among candidates plus O(N k m^2)
for the swaps, gradients O(N m d^2): O(N k) in
``N``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.spatial import cKDTree

from rapt.errors import InputError
from rapt.samplers.base import Sampler
from rapt.samplers.space_filling import sobol_points

__all__ = ["LolaVoronoiSampler", "neighbourhood_score", "lola_gradients", "voronoi_volumes"]


def neighbourhood_score(offsets: np.ndarray) -> np.ndarray:
    """LOLA's neighbourhood score ``S = R / C`` of neighbourhoods given as offsets from their sample.

    ``offsets`` has shape (..., m, d): neighbour minus reference sample.  Larger is better:
    neighbours close to the sample (small cohesion) and spread around it (the ideal is a
    cross-polytope, ``R = 1``).  A neighbourhood with a neighbour at distance 0 scores 0.
    """
    dist = np.linalg.norm(offsets, axis=-1)
    cohesion = dist.mean(axis=-1)
    d = offsets.shape[-1]
    if d == 1:  # the paper's 1-D ratio: 1 when the two neighbours straddle the sample symmetrically
        a, b = offsets[..., 0, 0], offsets[..., 1, 0]
        total = np.abs(a) + np.abs(b) + np.abs(a - b)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = 1.0 - np.abs(a + b) / total
    else:
        pair = np.linalg.norm(offsets[..., :, None, :] - offsets[..., None, :, :], axis=-1)
        m = offsets.shape[-2]
        pair[..., np.arange(m), np.arange(m)] = np.inf
        adhesion = pair.min(axis=-1).mean(axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = adhesion / (np.sqrt(2.0) * cohesion)
    with np.errstate(invalid="ignore", divide="ignore"):
        score = ratio / cohesion
    return np.where(np.isfinite(score) & (dist.min(axis=-1) > 0), score, 0.0)


def _neighbourhoods(X: np.ndarray, m: int, k: int) -> np.ndarray:
    """Indices (N, m) of each sample's LOLA neighbourhood, chosen greedily among its ``k`` nearest samples.

    Candidates are tried closest first; each replaces the member whose swap raises the
    score most, if any does.  Rows of ``X`` must be distinct.
    """
    dist, cand = cKDTree(X).query(X, k=k + 1)
    dist, cand = dist[:, 1:], cand[:, 1:]  # drop the sample itself
    pos = np.tile(np.arange(m), (len(X), 1))  # members, as positions among the candidates
    score = neighbourhood_score(X[cand[:, :m]] - X[:, None, :])
    if X.shape[1] == 1:  # the 1-D ratio has no adhesion: score every swap directly
        swap = lambda c: neighbourhood_score(_swapped(X, cand, pos, c) - X[:, None, None, :])  # noqa: E731
    else:
        P = X[cand]
        between = np.linalg.norm(P[:, :, None, :] - P[:, None, :, :], axis=-1)  # (N, k, k)
        swap = lambda c: _swap_scores(between, dist, pos, c)  # noqa: E731
    rows = np.arange(len(X))
    for c in range(m, k):
        trial = swap(c)  # (N, m): the score with member r replaced by candidate c
        best = trial.argmax(axis=1)
        better = trial[rows, best] > score
        pos[rows[better], best[better]] = c
        score = np.where(better, trial[rows, best], score)
    return cand[rows[:, None], pos]


def _swapped(X: np.ndarray, cand: np.ndarray, pos: np.ndarray, c: int) -> np.ndarray:
    """Coordinates (N, m swaps, m, d) of every neighbourhood with one member replaced by candidate ``c``."""
    m = pos.shape[1]
    trial = np.repeat(cand[np.arange(len(X))[:, None], pos][:, None, :], m, axis=1)
    trial[:, np.arange(m), np.arange(m)] = cand[:, c : c + 1]
    return X[trial]


def _min_excluding(D: np.ndarray) -> np.ndarray:
    """``out[..., i, r] = min_{j != r} D[..., i, j]`` (the smallest and second smallest per row)."""
    first = D.argmin(axis=-1)
    low = np.take_along_axis(D, first[..., None], axis=-1)
    rest = D.copy()
    np.put_along_axis(rest, first[..., None], np.inf, axis=-1)
    second = rest.min(axis=-1, keepdims=True)
    r = np.arange(D.shape[-1])
    return np.where(first[..., None] == r, second, low)


def _swap_scores(between: np.ndarray, dist: np.ndarray, pos: np.ndarray, c: int) -> np.ndarray:
    """Neighbourhood scores (N, m) of the neighbourhoods ``pos`` with member ``r`` replaced by candidate ``c``.

    ``between`` (N, k, k): distances between candidates; ``dist`` (N, k): candidate to
    sample.  O(N m^2) from the distances, where rescoring each swap costs O(N m^3 d).
    """
    n, m = pos.shape
    rows = np.arange(n)[:, None, None]
    M = between[rows, pos[:, :, None], pos[:, None, :]]  # (N, m, m) among members
    M[:, np.arange(m), np.arange(m)] = np.inf
    to_c = between[np.arange(n)[:, None], c, pos]  # (N, m) from each member to c
    nearest = np.minimum(_min_excluding(M), to_c[:, :, None])  # [i, r]: member i's nearest once r is out
    nearest[:, np.arange(m), np.arange(m)] = 0.0  # the member swapped out contributes nothing
    own = _min_excluding(to_c[:, None, :])[:, 0, :]  # [r]: c's nearest member other than r
    adhesion = (nearest.sum(axis=1) + own) / m
    member = np.take_along_axis(dist, pos, axis=1)
    cohesion = (member.sum(axis=1, keepdims=True) - member + dist[:, c : c + 1]) / m
    return adhesion / (np.sqrt(2.0) * cohesion**2)


def lola_gradients(X: np.ndarray, F: np.ndarray, hood: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares local gradients and LOLA nonlinearities.

    ``F`` is (N, q) (q output columns, e.g. class indicators); ``hood`` (N, m) neighbour
    indices.  Returns gradients (N, d, q) and the nonlinearity per sample and column
    (N, q): ``sum_j |F_j - F_p - g . (x_j - x_p)|`` over the neighbours ``j``.
    """
    dX = X[hood] - X[:, None, :]  # (N, m, d)
    dF = F[hood] - F[:, None, :]  # (N, m, q)
    grad = np.linalg.pinv(dX) @ dF  # (N, d, q)
    residual = dF - dX @ grad
    return grad, np.abs(residual).sum(axis=1)


def voronoi_volumes(X: np.ndarray, T: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Monte Carlo Voronoi cell volumes of the unit cube: (volume per sample, owner and distance per test point)."""
    dist, owner = cKDTree(X).query(T, k=1)
    return np.bincount(owner, minlength=len(X)) / len(T), owner, dist


def _output_columns(Y: np.ndarray, types: Sequence[str]) -> list[np.ndarray]:
    """Per output, the columns LOLA fits: class indicators (one vs rest) or the continuous score."""
    out = []
    for j, kind in enumerate(types):
        col = Y[:, j]
        if kind == "continuous":
            out.append(col[:, None].astype(float))
        else:
            out.append((col[:, None] == np.unique(col)[None, :]).astype(float))
    return out


class LolaVoronoiSampler(Sampler):
    """LOLA-Voronoi hybrid sequential design (see the module docstring).

    Parameters
    ----------
    test_points_per_sample, max_test_points:
        Monte Carlo points per batch: ``test_points_per_sample`` per sample (the paper's
        100), at most ``max_test_points``; they estimate cell volumes and are the
        candidates for new points.
    neighbour_candidates:
        Nearest samples searched for each neighbourhood, as a multiple of ``m = 2d``.
    n_initial:
        Batches come from a scrambled Sobol sequence until this many distinct samples
        (at least ``2d + 2``, the fewest LOLA can fit) have been told.
    """

    name = "lola-voronoi"
    adaptive = True

    def __init__(
        self,
        dim: int,
        *,
        seed: int = 0,
        output_types: Sequence[str] | None = None,
        test_points_per_sample: int = 100,
        max_test_points: int = 500_000,
        neighbour_candidates: int = 3,
        n_initial: int = 0,
    ):
        super().__init__(dim, seed=seed, output_types=output_types)
        for key, value in (
            ("test_points_per_sample", test_points_per_sample),
            ("max_test_points", max_test_points),
            ("neighbour_candidates", neighbour_candidates),
        ):
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < 1:
                raise InputError(f"{key}: expected a positive integer, got {value!r}")
        if not isinstance(n_initial, (int, np.integer)) or n_initial < 0:
            raise InputError(f"n_initial: expected a non-negative integer, got {n_initial!r}")
        self.test_points_per_sample = int(test_points_per_sample)
        self.max_test_points = int(max_test_points)
        self.neighbour_candidates = int(neighbour_candidates)
        self.n_initial = int(n_initial)
        self.m = 2 * self.dim
        self.last_scores: np.ndarray | None = None

    def _merged(self) -> tuple[np.ndarray, list[np.ndarray]]:
        """Distinct states (sorted, so the order of rows told does not matter) and their averaged output columns."""
        X, Y = self.X, self.Y
        Xu, inverse = np.unique(X, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        counts = np.bincount(inverse, minlength=len(Xu))[:, None]
        cols = []
        for F in _output_columns(Y, self.output_types or ("continuous",) * Y.shape[1]):
            sums = np.zeros((len(Xu), F.shape[1]))
            np.add.at(sums, inverse, F)
            cols.append(sums / counts)
        return Xu, cols

    def scores(self, X: np.ndarray, cols: list[np.ndarray], T: np.ndarray):
        """(H, V, E, owner, distance) for distinct samples ``X``, output columns ``cols`` and test points ``T``."""
        k = min(self.neighbour_candidates * self.m, len(X) - 1)
        hood = _neighbourhoods(X, self.m, k)
        E = np.zeros(len(X))
        for F in cols:
            e = lola_gradients(X, F, hood)[1].sum(axis=1)
            if e.sum() > 0:
                E += e / e.sum()
        E = E / len(cols)
        V, owner, dist = voronoi_volumes(X, T)
        return V + E, V, E, owner, dist

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        X, cols = self._merged()
        if len(X) < max(self.n_initial, self.m + 2):
            self.last_scores = None
            return sobol_points(self.dim, self.seed, self.n_asked, n)
        n_test = int(min(self.test_points_per_sample * len(X), self.max_test_points))
        T = rng.random((max(n_test, 4 * n), self.dim))
        H, _, _, owner, dist = self.scores(X, cols, T)
        self.last_scores = H
        return _place(H, owner, dist, T, n)


def _place(H: np.ndarray, owner: np.ndarray, dist: np.ndarray, T: np.ndarray, n: int) -> np.ndarray:
    """``n`` test points: one per cell in decreasing ``H`` (cycling when n exceeds the cells), each the
    point of its cell farthest from every sample and from the points already placed."""
    order = np.argsort(owner, kind="stable")
    starts = np.searchsorted(owner[order], np.arange(len(H) + 1))
    ranking = np.argsort(-H, kind="stable")
    ranking = ranking[starts[ranking + 1] > starts[ranking]]  # cells holding test points
    free = np.ones(len(T), dtype=bool)
    chosen: list[int] = []
    while len(chosen) < n:
        for cell in ranking:
            members = order[starts[cell] : starts[cell + 1]]
            members = members[free[members]]
            if not len(members):
                continue
            gap = dist[members]
            if chosen:
                gap = np.minimum(gap, cKDTree(T[chosen]).query(T[members], k=1)[0])
            pick = int(members[np.argmax(gap)])
            chosen.append(pick)
            free[pick] = False
            if len(chosen) == n:
                break
    return T[chosen]
