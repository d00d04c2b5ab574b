"""Sharp pairs: each candidate pair focused on its own score elements (section 4.3.6).

The search steers on the mission's root scores, so a pair on a sub-boundary comes out of
it far apart. A range cannot fly such a pair as a test of one boundary: its two scenarios
differ in much else besides. Each candidate pair gets a focused search of its own
(:func:`rapt.focus.sharpen_pairs`). That search is scored on the pair's outcome: the root
scores and the elements that differ across the pair. It stops once the pair is within
``2 * min_distance`` or its runs are spent. A candidate still further apart than
``max_distance`` is dropped, and the next candidate, on another sub-boundary, takes its
place.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import sim.uuv
from planner.plan.dithering import Outcome, outcome_columns
from rapt.focus import OTHER, SIDE_A, SIDE_B, sharpen_pairs
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["FOCUS_BATCH", "MIN_REFINE_RUNS", "refine_pairs"]

#: Runs per round of one pair's focused search: a midpoint and S-NDV's picks around it.
FOCUS_BATCH = 8
#: Fewer runs than two rounds cannot both bisect and go round a third combination.
MIN_REFINE_RUNS = 2 * FOCUS_BATCH


def refine_pairs(
    mission: Mission,
    a: Any,
    candidates: list[dict],
    k: int,
    *,
    runs: int,
    min_distance: float,
    max_distance: float,
    seed: int,
    surrogate=None,
) -> tuple[list[dict], dict]:
    """The first ``k`` candidates, in their order, that a focused search makes sharp.

    ``a`` is the study's :class:`~planner.plan.analysis.Analysis`: its runs seed each focus.
    ``runs`` caps each candidate's new simulations. Returns the sharp pairs and the
    refinement's account for the plan: runs spent, candidates tried, and the ones
    dropped with their lengths.
    """
    names = a.result.names
    root = list(a.tree.levels[0])
    sides = []  # per candidate, the outcomes of its two scenarios
    for p in candidates:
        cols = outcome_columns(root, names, p["elements"])
        sides.append(
            tuple(
                Outcome(MODE_NAMES.index(mode), tuple(cols), tuple(float(v) for v in a.result.scores[row, cols]))
                for row, mode in zip(p["rows"], p["modes"])
            )
        )
    X_known = np.vstack([a.X, a.X_invalid]) if len(a.X_invalid) else a.X
    n_valid = len(a.X)

    def label_rows(scores: np.ndarray, valid: np.ndarray, c: int) -> np.ndarray:
        out = np.full(len(scores), OTHER)
        out[sides[c][0].shown(scores, valid)] = SIDE_A
        out[sides[c][1].shown(scores, valid)] = SIDE_B
        return out

    def known_labels(c: int) -> np.ndarray:
        study = label_rows(a.result.scores, np.ones(n_valid, dtype=bool), c)
        return np.concatenate([study, np.full(len(X_known) - n_valid, OTHER)])

    def label(U: np.ndarray, owner: np.ndarray) -> np.ndarray:
        r = sim.uuv.simulate(mission, U, surrogate=surrogate)
        out = np.empty(len(U), dtype=np.int64)
        for c in np.unique(owner).tolist():
            rows = owner == c
            out[rows] = label_rows(r.scores[rows], r.valid[rows], c)
        return out

    outcomes = sharpen_pairs(
        label,
        [(a.X[p["rows"][0]], a.X[p["rows"][1]]) for p in candidates],
        k,
        runs=runs,
        min_distance=min_distance,
        max_distance=max_distance,
        seed=seed,
        batch=FOCUS_BATCH,
        known=(X_known, known_labels),
    )
    pairs: list[dict] = []
    dropped: list[dict] = []
    for o in outcomes:
        cand = candidates[o.candidate]
        if o.sharp and len(pairs) < k:
            pairs.append(
                {
                    **cand,
                    "distance": o.distance,
                    "start_distance": o.start_distance,
                    "refine_runs": o.runs,
                    "refined": True,
                    "u_override": [o.a, o.b],
                }
            )
        elif not o.sharp:
            dropped.append(
                {
                    "level": cand["level"],
                    "elements": cand["elements"],
                    "start_distance": o.start_distance,
                    "distance": o.distance,
                    "runs": o.runs,
                }
            )
    summary = {
        "runs_per_candidate": runs,
        "runs": int(sum(o.runs for o in outcomes)),
        "candidates": len(outcomes),
        "sharp": int(sum(o.sharp for o in outcomes)),
        "min_distance": min_distance,
        "max_distance": max_distance,
        "dropped": dropped,
    }
    return pairs, summary
