"""Re-plan under a fitted execution bias: which pairs no longer straddle, and "M" scenarios that do.

On the 2017 range day two pairs landed on the same side of their boundary and the team
moved them by hand — less starting fuel, a longer transmission window — so each side
showed its intended behaviour again (section 4.5.3-4.5.4, the "M" scenarios).  Here that
is automatic: every plan scenario is re-predicted by the batch simulator under the
fitted bias (the autonomy unbiased, the vehicle biased, as on the water); a pair is
flagged when a side no longer shows the values of its pair's score elements that the
plan predicted; and for each such side :func:`adjust_for_bias` searches the smallest move
along the plan's most sensitive coordinates, away from the pair's other scenario (the
direction :func:`planner.plan.dithering.robust_variants` also tries), that brings the intended
values back under the bias — checked by seeded stochastic dithers of the candidate, with
the bias, when asked.
"""

from __future__ import annotations

import numpy as np

import sim.uuv
from sim.uuv.bias import Bias
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["adjust_for_bias", "STEPS"]

#: Unit-cube moves tried, smallest first.
STEPS = (0.01, 0.02, 0.05, 0.1, 0.15, 0.2, 0.3)


def adjust_for_bias(
    mission: Mission,
    u: np.ndarray,
    partner: np.ndarray,
    cols: list[int],
    target: np.ndarray,
    bias: Bias,
    sensitivity: np.ndarray,
    *,
    coordinates: int = 3,
    dithers: int = 20,
    sigma: float = 0.02,
    p_target: float = 0.8,
    seed: int = 0,
) -> dict | None:
    """The smallest move of ``u`` whose run under ``bias`` shows ``target`` on score columns ``cols``.

    Candidates: each of the ``coordinates`` most sensitive coordinates, moved away from
    ``partner`` (both ways where the two agree) by each of :data:`STEPS`, simulated in one
    batch.  Among those that are valid and show ``target``, the smallest move wins whose
    ``dithers`` stochastic runs (with the bias) show ``target`` at least ``p_target`` of
    the time; failing that, the smallest deterministic match, marked ``robust: False``.
    None when no candidate shows ``target``.
    """
    u = np.asarray(u, dtype=float)
    order = np.argsort(-np.asarray(sensitivity, dtype=float), kind="stable")[:coordinates]
    cands, moves = [], []
    for c in order.tolist():
        away = np.sign(u[c] - partner[c])
        for direction in [away] if away else [1.0, -1.0]:
            for step in STEPS:
                v = u.copy()
                v[c] = np.clip(v[c] + direction * step, 0.0, 1.0)
                v = mission.space.snap(v[None, :])[0]  # as the range sets it
                if v[c] != u[c]:
                    cands.append(v)
                    moves.append((abs(v[c] - u[c]), int(c), float(v[c] - u[c])))
    if not cands:
        return None
    U = np.array(cands)
    r = sim.uuv.simulate(mission, U, bias=bias)
    hit = r.valid & np.all(r.scores[:, cols] == np.asarray(target)[None, :], axis=1)
    ranked = sorted(np.flatnonzero(hit).tolist(), key=lambda i: (moves[i][0], -sensitivity[moves[i][1]]))
    if not ranked:
        return None
    first = ranked[:4]  # dither the few smallest matches only, in one batch
    entries = [
        {
            "u": [float(x) for x in U[i]],
            "coordinate": moves[i][1],
            "unit_step": moves[i][2],
            "mode": MODE_NAMES[int(r.modes[i])],
            "p_intended": None,
            "robust": True,
        }
        for i in first
    ]
    if dithers <= 0:
        return entries[0]
    rng = np.random.default_rng(seed)
    D = np.clip(
        np.repeat(U[first], dithers, axis=0) + sigma * rng.standard_normal((len(first) * dithers, u.size)), 0.0, 1.0
    )
    D[::dithers] = U[first]  # each candidate itself, with the stochastic effects on
    d = sim.uuv.simulate(mission, D, seed=seed, stochastic=True, bias=bias)
    show = d.valid & np.all(d.scores[:, cols] == np.asarray(target)[None, :], axis=1)
    for j, entry in enumerate(entries):
        block = slice(j * dithers, (j + 1) * dithers)
        ok = d.valid[block]
        p_intended = float(show[block][ok].mean()) if ok.any() else 0.0
        entry["p_intended"] = p_intended
        if p_intended >= p_target:
            return entry
    return {**max(entries, key=lambda e: e["p_intended"]), "robust": False}
