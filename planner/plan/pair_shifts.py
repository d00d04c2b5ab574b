"""Pairs moved as a whole: a fragile pair's boundary tested where the day's noise flips neither side.

A side that flips under the day's noise sits too near its boundary. A variant moves that
side alone, away from its partner, and one that strays more than
:data:`~planner.plan.pair_choice.MAX_FLOWN_DISTANCE` from it no longer tests the boundary.
Moving both sides by one shift keeps the pair's length and the boundary between them: along
the pair's normal, away from the fragile side, so the boundary sits nearer the middle; or
along the boundary, to where it may be less sensitive. :func:`shifted_pairs` proposes the
shifts; :func:`with_shifted_pairs` screens them cheaply, confirms the best as the candidates
were confirmed, and sets them beside their origins to compete in the pair choice.
"""

from __future__ import annotations

import dataclasses
import itertools
import math

import numpy as np

from planner.plan.pair_choice import Candidate, Dithering, dither_candidates, write_candidates
from sim.uuv.mission import Mission

__all__ = [
    "SHIFTED_PER_PAIR",
    "SHIFTS_CONFIRMED",
    "SHIFT_SIGMAS",
    "shift_note",
    "shifted_pairs",
    "with_shifted_pairs",
]

#: A pair moved as a whole shifts by these many sigmas of the expected noise along the move: along its
#: normal (away from the fragile side) and both ways along the boundary on its two noisiest coordinates.
SHIFT_SIGMAS = (1.0, 2.0)
#: Sub-boundaries (most likely to straddle first, per pair the plan needs) whose fragile pairs are moved.
SHIFTED_PER_PAIR = 2
#: Of each candidate's shifts, the best screened this many are dithered in full and given variants: a shift
#: that screens well as written may still need a variant to hold, and the two best are what that costs.
SHIFTS_CONFIRMED = 2


def shifted_pairs(candidates: list[Candidate], sigma: np.ndarray, target: float, limit: int) -> list[dict]:
    """Pairs moved as a whole, for up to ``limit`` sub-boundaries that no candidate holds on: the candidate
    of each most likely to straddle, where a flown side holds under ``target``; each a candidate pair dict
    with ``u_override`` (its two scenarios), ``shifted`` (how it was moved) and ``shift_of`` (its
    candidate's index).

    A sub-boundary with a candidate whose flown sides both hold needs no move: the plan keeps one
    pair per sub-boundary, and that one already shows. The moves are along the pair's normal, away
    from the fragile side, when the other side holds, and both ways along the boundary on the two
    noisiest coordinates across the normal. Each is :data:`SHIFT_SIGMAS` of the noise along it; one
    that would leave the unit cube is not tried.
    """
    sigma = np.asarray(sigma, dtype=float)
    order = sorted(range(len(candidates)), key=lambda i: -(candidates[i].p_straddle or 0.0))
    flown = {i: [float(p) for p in candidates[i].flown_p if p is not None] for i in order}
    held = {candidates[i].sub_boundary for i in order if len(flown[i]) == 2 and min(flown[i]) >= target}
    out: list[dict] = []
    seen: set[tuple] = set()
    for i in order:
        cand, key = candidates[i], candidates[i].sub_boundary
        if len(flown[i]) < 2 or key in held or key in seen:
            continue
        seen.add(key)
        if len(seen) > limit:
            break
        for along, direction in _moves(cand.U, [p < target for p in flown[i]], sigma):
            step = math.hypot(*(direction * sigma))  # one sigma of noise along the move
            for k in SHIFT_SIGMAS:
                shift = k * step * direction
                U = cand.U + shift
                if np.any(U < 0.0) or np.any(U > 1.0):
                    continue
                shifted = {"along": along, "sigmas": k, "by": math.hypot(*shift)}
                out.append({**cand.pair, "u_override": U, "shifted": shifted, "shift_of": i})
    return out


def _moves(U: np.ndarray, fragile: list[bool], sigma: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """Unit directions to move a pair ``U`` (2, d) in: its normal, away from a lone fragile side, then
    both ways along the boundary on the two coordinates noisiest across the normal."""
    delta = U[1] - U[0]
    d = math.hypot(*delta)  # not BLAS: the same bits on every machine
    if d == 0.0:
        return []
    normal = delta / d
    moves: list[tuple[str, np.ndarray]] = []
    if fragile[0] != fragile[1]:  # one side holds: move toward it, the fragile one away from the boundary
        moves.append(("normal", normal if fragile[1] else -normal))
    across = np.eye(normal.size) - np.outer(normal, normal)
    for j in np.argsort(-np.abs(sigma * np.diag(across)), kind="stable")[:2]:
        t = across[:, j]
        if math.hypot(*t) > 1e-6:
            t = t / math.hypot(*t)
            moves += [("boundary", t), ("boundary", -t)]
    return moves


def with_shifted_pairs(
    mission: Mission, tree_levels: list, evaluated: list[Candidate], how: Dithering, *, pairs: int, budget: int
) -> tuple[list[Candidate], int]:
    """The candidates with, after each, its best moves as a whole where they straddle more often; the runs spent.

    Every shift of :func:`shifted_pairs` (for :data:`SHIFTED_PER_PAIR` times ``pairs`` sub-boundaries)
    is written once and screened as written with ``how.dithers``/20 dithers per side (as a variant is).
    Those that straddle more often than their candidate as written are confirmed in rounds, each
    candidate's best in the first, its second best in the next, up to :data:`SHIFTS_CONFIRMED`: dithered
    again with ``how.dithers`` and a fresh seed, and given variants as the candidates were, so their P
    comes from the confirmation alone, not from the screen that chose them. A round starts only
    while the shifts have spent under ``budget`` runs (the candidates' own dithering and variants):
    moving pairs refines the plan at about the cost of choosing them.
    """
    if not how.dithers:
        return evaluated, 0
    shifted = shifted_pairs(evaluated, how.sigma, how.target, SHIFTED_PER_PAIR * pairs)
    if not shifted:
        return evaluated, 0
    moved = write_candidates(mission, tree_levels, shifted, lambda pair: np.asarray(pair["u_override"], dtype=float))
    screen = dataclasses.replace(how, dithers=2 * min(max(how.dithers // 20, 40), how.dithers // 2), seed=how.seed + 2)
    runs = 2 * len(shifted) + sum(dither_candidates(mission, moved, screen, variants=False).values())

    def written(c: Candidate) -> float:
        """P(straddle) of the pair as written, neither side's variant flown."""
        return float(np.prod([c.stats[s].get("p_predicted") or 0.0 for s in (0, 1)]))

    better = [m for m in moved if written(m) > written(evaluated[m.pair["shift_of"]])]
    better.sort(key=lambda m: (m.pair["shift_of"], -written(m)))  # stable: each candidate's best first
    ranked = [list(same) for _, same in itertools.groupby(better, key=lambda m: m.pair["shift_of"])]
    best: list[Candidate] = []
    for r in range(SHIFTS_CONFIRMED):
        batch = [shifts[r] for shifts in ranked if len(shifts) > r]
        if not batch or runs >= budget:
            break
        runs += sum(dither_candidates(mission, batch, dataclasses.replace(how, seed=how.seed + 3 + r)).values())
        best += batch
    out: list[Candidate] = []
    for i, cand in enumerate(evaluated):
        out.append(cand)
        out += [m for m in best if m.pair["shift_of"] == i]
    return out, runs


def shift_note(shifted: dict) -> str:
    """How a plan's pair was moved, in words for the summary and the report (``shifted`` as in plan.json)."""
    where = (
        "along its boundary" if shifted["along"] == "boundary" else "across its boundary, away from its fragile side"
    )
    k = shifted["sigmas"]
    return f"moved as a whole {k:g} noise sigma{'' if k == 1 else 's'} {where} ({shifted['by']:.3f} in the unit cube)"
