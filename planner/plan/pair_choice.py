"""The pairs a range will see: candidates ranked by the chance that both flown sides show their outcomes.

A pair tells the range about a boundary only when, on the day, both of its flown scenarios
show what the plan predicts for them: side a its outcome, side b its own. Each side is its
own run on the water under its own execution noise, so that chance, P(straddle), is the
product of the two sides' dithered probabilities, each side taken as the range flies it (its
robust "M" variant where one was found, the scenario itself otherwise). Distance alone
does not rank pairs: a short pair on a sensitive stretch of its boundary flips on every
metre of navigation error, while a slightly longer one elsewhere holds.

:func:`evaluate_candidates` takes every candidate pair (more than the plan needs), writes
its sides at the range's resolution, simulates them, keeps only those whose written sides
still differ on the pair's elements (the pair's modes and elements are then those of its
written scenarios, so the plan agrees with itself), dithers them, and looks for robust
variants of the fragile sides (:func:`write_candidates`, then :func:`dither_candidates`; pairs
moved as a whole, :mod:`planner.plan.pair_shifts`, go through the same two steps).
:func:`rank_candidates` then keeps the ``k`` most likely to
show, one per sub-boundary, with the flown sides no farther apart than
:data:`MAX_FLOWN_DISTANCE`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from itertools import product
from typing import Any

import numpy as np

import sim.uuv
from planner.plan.dithering import Outcome, dither_many, outcome_columns, robust_variants
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = [
    "MAX_FLOWN_DISTANCE",
    "Candidate",
    "Dithering",
    "dither_candidates",
    "evaluate_candidates",
    "rank_candidates",
    "write_candidates",
]

#: A flown variant keeps its pair's sides at most this far apart in the unit cube (or no farther than
#: the written pair): farther, the switch between them is no longer one boundary's.
MAX_FLOWN_DISTANCE = 0.25


@dataclass
class Candidate:
    """One candidate pair as written, dithered and (where a side is fragile) given variants."""

    pair: dict  # the analysis' pair: level, elements, modes, distance (updated to the written sides)
    U: np.ndarray  # (2, d): the written sides, at the range's resolution
    outcomes: list[Outcome]
    stats: list[dict] = field(default_factory=lambda: [{}, {}])
    dithers: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # per side: rows, modes
    variants: list[dict | None] = field(default_factory=lambda: [None, None])  # robust_variants' entry per side
    flies_variant: list[bool] = field(default_factory=lambda: [False, False])

    def variant(self, side: int) -> dict | None:
        """The side's variant: one that holds at the target, else the closest confirmed under it (None: none)."""
        v = self.variants[side]
        if v is None:
            return None
        return v if v.get("found") else v.get("closest")

    def p_side(self, side: int, variant: bool) -> float | None:
        if variant:
            v = self.variant(side)
            return None if v is None else float(v["p_predicted"])
        return self.stats[side].get("p_predicted")

    def flown_u(self, side: int, variant: bool | None = None) -> np.ndarray:
        use = self.flies_variant[side] if variant is None else variant
        v = self.variant(side)
        return np.asarray(v["u"], dtype=float) if use and v is not None else self.U[side]

    @property
    def flown_p(self) -> list[float | None]:
        """Each flown side's dithered P (its variant's where one is flown; None undithered)."""
        return [self.p_side(s, self.flies_variant[s]) for s in (0, 1)]

    @property
    def p_straddle(self) -> float | None:
        """P(both flown sides show their outcomes): the product of the flown sides' dithered P (None undithered)."""
        p = self.flown_p
        return None if None in p else float(p[0] * p[1])  # type: ignore[operator]

    @property
    def sub_boundary(self) -> tuple:
        """The sub-boundary the pair straddles (its level and elements): the plan keeps one pair per sub-boundary."""
        return (self.pair["level"], tuple(self.pair["elements"]))

    @property
    def flown_distance(self) -> float:
        return math.dist(self.flown_u(0), self.flown_u(1))

    def choose_flown(self, target: float) -> None:
        """Per side, the scenario or its variant: the combination most likely to straddle, the flown sides within
        :data:`MAX_FLOWN_DISTANCE` (or the written pair's own length, when longer); a side already at ``target`` keeps its scenario (the shorter pair)."""
        best: tuple[float, float, tuple[bool, ...]] | None = None
        for use in product((False, True), repeat=2):
            p = [self.p_side(s, use[s]) for s in (0, 1)]
            own = [self.stats[s].get("p_predicted") or 0.0 for s in (0, 1)]
            if None in p or any(use[s] and (own[s] >= target or p[s] <= own[s]) for s in (0, 1)):  # type: ignore[operator]
                continue  # a variant flies only for a fragile side, and only where it holds more often
            d = math.dist(self.flown_u(0, use[0]), self.flown_u(1, use[1]))
            if any(use) and d > max(MAX_FLOWN_DISTANCE, self.pair["distance"]):
                continue
            key = (float(p[0] * p[1]), -d, use)  # type: ignore[operator]
            if best is None or key[:2] > best[:2]:
                best = key
        self.flies_variant = list(best[2]) if best is not None else [False, False]


def _written_elements(tree_levels: list, names: list[str], types, scores: np.ndarray, level: int) -> list[str]:
    """The discrete score elements of ``level`` that differ between a pair's two written sides."""
    return [names[c] for c in tree_levels[level] if types[c] != "continuous" and scores[0, c] != scores[1, c]]


@dataclass(frozen=True)
class Dithering:
    """How candidate pairs are dithered: ``dithers`` runs a pair under the per-coordinate noise ``sigma``
    (unit cube), each side needing ``target``; ``sensitivity`` steers the variant search, ``seed`` its
    draws, and ``surrogate`` (when given) flies the dithers in place of the expert."""

    dithers: int
    sigma: np.ndarray
    sensitivity: np.ndarray
    target: float
    seed: int
    surrogate: Any = None


def evaluate_candidates(
    mission: Mission, tree_levels: list, candidates: list[dict], points: Callable[[dict], np.ndarray], how: Dithering
) -> tuple[list[Candidate], dict[str, int]]:
    """Every candidate written (:func:`write_candidates`), dithered and given variants (:func:`dither_candidates`);
    the runs each stage spent."""
    kept = write_candidates(mission, tree_levels, candidates, points)
    return kept, {"written": 2 * len(candidates)} | dither_candidates(mission, kept, how)


def write_candidates(
    mission: Mission, tree_levels: list, candidates: list[dict], points: Callable[[dict], np.ndarray]
) -> list[Candidate]:
    """The candidates whose sides, written at the range's resolution, still differ on their level's elements.

    ``points(pair)`` gives a candidate's two unit-cube scenarios. Each is snapped to the
    range's resolution a step away from its partner, so the boundary stays between them, and
    simulated once (two runs per candidate); a candidate whose written sides no longer differ
    on any element of its level is dropped.
    """
    U = np.vstack([points(p) for p in candidates]) if candidates else np.zeros((0, mission.dim))
    U = mission.space.snap(U, away_from=U[np.arange(len(U)) ^ 1])
    written = sim.uuv.simulate(mission, U)  # the plan predicts the expert autonomy; dithers may use a surrogate
    root = list(tree_levels[0])
    kept: list[Candidate] = []
    for c, pair in enumerate(candidates):
        rows = [2 * c, 2 * c + 1]
        scores = written.scores[rows]
        if not written.valid[rows].all():
            continue
        elements = _written_elements(tree_levels, written.names, written.output_types, scores, pair["level"])
        if not elements:
            continue  # the range's resolution closed the boundary: the sides show the same outcome
        cols = outcome_columns(root, written.names, elements)
        outcomes = [
            Outcome(int(written.modes[k]), tuple(cols), tuple(float(v) for v in written.scores[k, cols])) for k in rows
        ]
        modes = [MODE_NAMES[int(written.modes[k])] for k in rows]
        distance = math.dist(U[rows[0]], U[rows[1]])
        kept.append(Candidate({**pair, "elements": elements, "modes": modes, "distance": distance}, U[rows], outcomes))
    return kept


def dither_candidates(mission: Mission, kept: list[Candidate], how: Dithering, variants: bool = True) -> dict[str, int]:
    """Dither each written candidate's sides (``dithers`` runs a pair) and, with ``variants``, look for robust
    variants of the fragile ones; each candidate's stats, dithers, variants and flown sides are set in place.

    Returns the runs each stage spent. Dithering again (more runs, another seed) replaces a
    candidate's stats: a screened estimate is not pooled with its confirmation, as the screen
    chose the candidates on its own dithers and would carry their luck into the estimate.
    """
    runs = {"dithering": 0, "variants": 0}
    dithers, sigma, target, seed = how.dithers, how.sigma, how.target, how.seed
    if not dithers or not kept:
        return runs
    n = dithers // 2
    centres = np.vstack([c.U for c in kept])
    side_outcomes = [o for c in kept for o in c.outcomes]
    side_elements = [c.pair["elements"] for c in kept for _ in (0, 1)]
    stats, dU, dmodes, shown = dither_many(
        mission, centres, side_outcomes, side_elements, n, sigma, seed, how.surrogate
    )
    runs["dithering"] = len(centres) * n
    for c, cand in enumerate(kept):
        cand.stats = [stats[2 * c], stats[2 * c + 1]]
        cand.dithers = [(dU[2 * c + s], dmodes[2 * c + s]) for s in (0, 1)]
        cand.variants = [None, None]
    fragile = [k for k, st in enumerate(stats) if st.get("p_predicted", 1.0) < target] if variants else []
    if fragile:
        found, runs["variants"] = robust_variants(
            mission,
            centres[fragile],
            centres[np.asarray(fragile) ^ 1],
            [side_outcomes[k] for k in fragile],
            [(dU[k], shown[k]) for k in fragile],
            how.sensitivity,
            sigma,
            min(max(dithers // 20, 40), n),  # screening never outweighs confirming
            n,
            target,
            seed + 1,
            how.surrogate,
        )
        for k, v in zip(fragile, found):
            kept[k // 2].variants[k % 2] = v
    for cand in kept:
        cand.choose_flown(target)
    return runs


def rank_candidates(candidates: list[Candidate], k: int) -> list[Candidate]:
    """The ``k`` candidates most likely to straddle, one per sub-boundary (level and elements).

    They are returned in the candidates' own order (root-mode changes first, shortest first), which
    names the plan's pairs, so a plan whose choice did not change keeps its pair names. Ties in
    P(straddle), and undithered plans, also go by that order.
    """

    def likely(i: int) -> float:
        p = candidates[i].p_straddle
        return -1.0 if p is None else p

    order = sorted(range(len(candidates)), key=lambda i: (-likely(i), i))
    chosen: list[int] = []
    seen: set[tuple] = set()
    for i in order:
        key = candidates[i].sub_boundary
        if key in seen:
            continue
        seen.add(key)
        chosen.append(i)
        if len(chosen) == k:
            break
    return [candidates[i] for i in sorted(chosen)]
