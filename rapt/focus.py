"""Focused pair search: sharpen a boundary pair on its own labels (section 4.3.6).

A search steered by the root scores samples the primary boundaries finely and the
sub-boundaries inside the modes coarsely, so the pairs it leaves on a sub-boundary are far
apart.  Section 4.3.6 asks for a second round of simulations around each chosen pair,
scored on the pair's own score elements.  :class:`PairFocus` is that round for one pair.
Every sample is labelled :data:`SIDE_A` (the first scenario's combination of the pair's
elements), :data:`SIDE_B` (the second's) or :data:`OTHER` (any other combination, or an
invalid scenario).  The pair is the closest A-B pair found so far.

Each round asks:

* the midpoint of the current pair. This is bisection, the best single move while the
  segment crosses only this boundary;
* S-NDV's picks (eq. 3.8, labels as one categorical output) among candidates drawn around
  the current pair's segment, inside the ball of the pair's length about its midpoint.
  When the midpoint shows a third combination, the next pair is found around it instead
  of the search stopping there.

:func:`sharpen_pairs` runs many foci in lock-step, one evaluation per round for all of
them. A candidate that cannot be sharpened is replaced by the next, so only sharp pairs
are returned.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from rapt.errors import InputError
from rapt.samplers.adaptive import ScaledNDVSampler

__all__ = ["SIDE_A", "SIDE_B", "OTHER", "PairFocus", "FocusOutcome", "sharpen_pairs"]

SIDE_A, SIDE_B, OTHER = 0, 1, 2

#: Candidates' offset from the pair's segment, as a share of the pair's length (the norm of
#: the offset, whatever the dimension): wide enough to step round a third combination on
#: the segment, narrow enough that a new pair is shorter than the one it replaces.
SPREAD = 1.0
#: S-NDV's neighbours per candidate. The focus starts from a handful of samples, so k is
#: smaller than a whole study's.
FOCUS_K = 4
#: Least offset scale of a coordinate, relative to the most important one's.
IMPORTANCE_FLOOR = 0.2


class _SegmentCandidates:
    """Candidates around the current pair's segment, within its ball (a PairFocus's generator)."""

    def __init__(self, focus: PairFocus):
        self.focus = focus

    def __call__(self, n: int, rng: np.random.Generator, sampler) -> np.ndarray:
        return self.focus._around_segment(n, rng)


class PairFocus:
    """Ask/tell search for the closest pair across one sub-boundary, near a given pair.

    ``a`` and ``b`` are unit-cube scenarios labelled :data:`SIDE_A` and :data:`SIDE_B`.
    ``X_known`` and ``labels_known`` are samples already evaluated (the study's). Those
    inside the pair's ball seed the search and cost nothing. ``runs`` caps the new
    evaluations. The focus is done when they are spent, or when the pair is shorter
    than ``2 * min_distance``: a pair closer than ``min_distance`` cannot be told apart
    on the water (section 4.1), so halving it again would overshoot.
    """

    def __init__(
        self,
        a: np.ndarray,
        b: np.ndarray,
        *,
        runs: int,
        min_distance: float,
        batch: int = 8,
        seed: int = 0,
        X_known: np.ndarray | None = None,
        labels_known: np.ndarray | None = None,
    ):
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        if a.ndim != 1 or a.shape != b.shape:
            raise InputError(f"a, b: expected two unit-cube rows of one length, got shapes {a.shape} and {b.shape}")
        if not isinstance(runs, (int, np.integer)) or runs < 0:
            raise InputError(f"runs: expected a number of runs >= 0, got {runs!r}")
        if not isinstance(batch, (int, np.integer)) or batch < 1:
            raise InputError(f"batch: expected a positive number of runs per round, got {batch!r}")
        if not (min_distance >= 0 and np.isfinite(min_distance)):
            raise InputError(f"min_distance: expected a finite distance >= 0, got {min_distance!r}")
        self.dim = a.shape[0]
        self.runs, self.batch, self.min_distance = int(runs), int(batch), float(min_distance)
        self.spent = 0
        self.start_distance = math.dist(a, b)
        self._X = [a[None, :], b[None, :]]
        self._labels = [np.array([SIDE_A, SIDE_B])]
        self._asked: set[bytes] = set()
        if X_known is not None and len(X_known):
            Xk = np.asarray(X_known, dtype=float)
            lk = np.asarray(labels_known)
            if Xk.shape != (lk.shape[0], self.dim):
                raise InputError(f"X_known: expected ({lk.shape[0]}, {self.dim}) rows, got {Xk.shape}")
            near = np.linalg.norm(Xk - (a + b) / 2, axis=1) <= self.start_distance
            self._X.append(Xk[near])
            self._labels.append(lk[near].astype(np.int64))
        self.a, self.b = a, b
        self.sampler = ScaledNDVSampler(
            self.dim,
            seed=int(seed),
            k=FOCUS_K,
            output_types=("categorical",),
            candidate_generator=_SegmentCandidates(self),
            min_candidates=200,
        )
        X, labels = self.data()
        self.sampler.tell(X, labels[:, None].astype(float))
        self._repair()

    # -- state ------------------------------------------------------------------------
    def data(self) -> tuple[np.ndarray, np.ndarray]:
        """Every sample the focus knows (the pair, the known ones in its ball, its own runs) and their labels."""
        return np.concatenate(self._X), np.concatenate(self._labels)

    @property
    def distance(self) -> float:
        return math.dist(self.a, self.b)

    @property
    def done(self) -> bool:
        return self.spent >= self.runs or self.distance < 2 * self.min_distance

    # -- ask / tell ---------------------------------------------------------------------
    def ask(self) -> np.ndarray:
        """The next round's scenarios (none once :attr:`done`)."""
        n = min(self.batch, self.runs - self.spent)
        if self.done or n < 1:
            return np.empty((0, self.dim))
        rows = []
        mid = (self.a + self.b) / 2
        if mid.tobytes() not in self._asked:
            rows.append(mid)
        if n > len(rows):
            if self.sampler.n_told > FOCUS_K:
                rows.extend(self.sampler.ask(n - len(rows)))
            else:  # too few samples for S-NDV's neighbours yet: spread the first round round the segment
                rng = np.random.default_rng(np.random.SeedSequence([self.sampler.seed, self.spent]))
                rows.extend(self._around_segment(n - len(rows), rng))
        out = np.clip(np.array(rows), 0.0, 1.0)
        self._asked.update(r.tobytes() for r in out)
        return out

    def tell(self, U: np.ndarray, labels: np.ndarray) -> None:
        """Record evaluated scenarios (labels :data:`SIDE_A`, :data:`SIDE_B` or :data:`OTHER`); re-pair."""
        U = np.atleast_2d(np.asarray(U, dtype=float))
        labels = np.asarray(labels, dtype=np.int64).reshape(-1)
        if U.shape != (labels.shape[0], self.dim) or not np.isin(labels, (SIDE_A, SIDE_B, OTHER)).all():
            raise InputError(f"tell: expected ({labels.shape[0]}, {self.dim}) rows labelled 0, 1 or 2")
        self.spent += len(U)
        self._X.append(U)
        self._labels.append(labels)
        self.sampler.tell(U, labels[:, None].astype(float))
        self._repair()

    def _repair(self) -> None:
        """The closest A-B pair at least ``min_distance`` apart becomes the pair."""
        X, labels = self.data()
        A, B = X[labels == SIDE_A], X[labels == SIDE_B]
        d = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
        d[d < self.min_distance] = np.inf
        i, j = np.unravel_index(np.argmin(d), d.shape)
        if d[i, j] < self.distance:
            self.a, self.b = A[i], B[j]

    def _around_segment(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``n`` points near the segment a-b, inside the ball of its length about its midpoint."""
        length = self.distance
        t = rng.random((n, 1))
        # Offsets along the coordinates S-NDV found to matter: in an unimportant one they
        # only lengthen the pair.  Scaled so the offset's expected norm is SPREAD * length.
        # Half the candidates stay isotropic, so that a coordinate S-NDV has not yet seen
        # matter (the way round a third combination) keeps being explored.
        w = self.sampler.weights_
        scale = np.ones(self.dim) if w is None else np.maximum(w.max(axis=0), IMPORTANCE_FLOOR)
        scale *= SPREAD * length / math.hypot(*scale)
        iso = np.full(self.dim, SPREAD * length / np.sqrt(self.dim))
        offset = rng.standard_normal((n, self.dim)) * np.where(np.arange(n)[:, None] % 2 == 0, scale, iso)
        P = self.a + t * (self.b - self.a) + offset
        mid = (self.a + self.b) / 2
        r = np.linalg.norm(P - mid, axis=1, keepdims=True)
        P = mid + (P - mid) * np.minimum(1.0, length / np.maximum(r, 1e-300))
        return np.clip(P, 0.0, 1.0)


@dataclass
class FocusOutcome:
    """One candidate pair after its focused search."""

    candidate: int  # index into the candidates given
    a: np.ndarray
    b: np.ndarray
    start_distance: float
    distance: float
    runs: int
    sharp: bool


def sharpen_pairs(
    label: Callable[[np.ndarray, np.ndarray], np.ndarray],
    candidates: Sequence[tuple[np.ndarray, np.ndarray]],
    k: int,
    *,
    runs: int,
    min_distance: float,
    max_distance: float,
    seed: int = 0,
    batch: int = 8,
    known: tuple[np.ndarray, Callable[[int], np.ndarray]] | None = None,
) -> list[FocusOutcome]:
    """Focus candidates in rank order until ``k`` come out sharp (at most ``max_distance`` apart).

    ``label(U, owner)`` evaluates rows ``U`` (all foci's in one call) and labels each for
    the candidate ``owner[r]`` it was asked for: :data:`SIDE_A`, :data:`SIDE_B` or
    :data:`OTHER`. ``known`` is ``(X, labels_of)``, the study's samples and a function
    giving their labels for candidate ``c``. Up to ``k`` foci run at once. A candidate
    already sharp with no new runs needs none. One that ends longer than
    ``max_distance`` is dropped, and the next candidate takes its place. Returns every
    candidate tried, in candidate order (``sharp`` marks the ones to ship).
    """
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise InputError(f"k: expected a positive number of pairs, got {k!r}")
    if not (0 <= min_distance < max_distance):
        raise InputError(f"max_distance: expected more than min_distance ({min_distance}), got {max_distance}")
    outcomes: list[FocusOutcome] = []
    active: dict[int, PairFocus] = {}
    queue = list(range(len(candidates)))

    def finish(c: int, f: PairFocus) -> None:
        sharp = f.distance <= max_distance
        outcomes.append(FocusOutcome(c, f.a, f.b, f.start_distance, f.distance, f.spent, sharp))

    while True:
        wanted = k - sum(o.sharp for o in outcomes)
        while queue and len(active) < wanted:
            c = queue.pop(0)
            X_known, labels_known = (None, None) if known is None else (known[0], known[1](c))
            f = PairFocus(
                *candidates[c],
                runs=runs,
                min_distance=min_distance,
                batch=batch,
                seed=int(np.random.SeedSequence([seed, c]).generate_state(1)[0]),
                X_known=X_known,
                labels_known=labels_known,
            )
            if f.done and f.distance <= max_distance:  # nothing to gain
                finish(c, f)
                wanted -= 1
            else:
                active[c] = f
        if not active:
            break
        asks = {c: f.ask() for c, f in active.items()}
        owners = np.concatenate([np.full(len(u), c) for c, u in asks.items()]).astype(np.int64)
        if owners.size:
            U = np.vstack(list(asks.values()))
            labels = np.asarray(label(U, owners))
            for c, f in active.items():
                rows = owners == c
                if rows.any():
                    f.tell(U[rows], labels[rows])
        for c in [c for c, f in active.items() if f.done or not len(asks[c])]:
            finish(c, active.pop(c))
    return sorted(outcomes, key=lambda o: o.candidate)
