"""The chance each side's scenario shows its outcome on its next run, with the noise fitted to what the day showed.

The forecasts also say how well they foresaw the runs so far (:attr:`SideForecasts.evidence`, the scale
integrated out): ``rapt-plan next`` forecasts with the afternoon's bias only when that foresaw the day's
outcomes at least as well as the plan's water did, the outcome-level counterpart of ``compare``'s
held-out check of a correction.

The plan dithers each scenario by the execution noise it was made with (``study.dithering.sigma_u``,
the morning's spread of tracks about their replays where the noon step fitted it).  That spread is
one number per kind for the whole day, while what decides a side is whether its runs show its
outcome: a day whose runs land as predicted is quieter, for these scenarios, than its tracks' spread
says.  So the noise's scale is fitted to the outcomes themselves (:func:`forecast_sides`): for each
scale of :data:`SCALES` the sides' scenarios are dithered (:func:`planner.common.execution_noise.dithered_runs`,
common random numbers across scales, each run under a draw of the afternoon's bias posterior), and
the runs flown so far weigh the scales by their likelihood,

    P(run | scale) = (1 - eps) * P_scale(showed or missed) + eps / 2,

``eps`` = :data:`CONTAMINATION` the chance that a run says nothing of the noise (a scenario the model
gets wrong whatever the noise: one such run must not drag the whole day's scale), under a
log-normal prior on the scale (:data:`SCALE_PRIOR_SD`, centred on the plan's noise).  Each
scenario's forecast is its P averaged over the scales' posterior.  With no run yet, that is the
plan's noise, with its uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.common.execution_noise import dithered_runs
from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, NEUTRAL
from sim.uuv.mission import Mission

__all__ = ["SCALES", "DRAWS", "CONTAMINATION", "SCALE_PRIOR_SD", "Target", "SideForecasts", "forecast_sides"]

#: Scales of the plan's execution noise weighed against the day's outcomes.
SCALES = (0.35, 0.5, 0.7, 1.0, 1.4)
#: Standard deviation of the log scale's prior (around the plan's noise, scale 1).
SCALE_PRIOR_SD = 0.5
#: Dithered runs per scenario and scale.
DRAWS = 48
#: The chance a run's outcome is not the noise's doing (the likelihood's floor; see the module docstring).
CONTAMINATION = 0.1


@dataclass(frozen=True)
class Target:
    """A scenario and the outcome it is flown to show: score columns and their values."""

    u: np.ndarray
    columns: tuple[int, ...]
    values: tuple[float, ...]


@dataclass
class SideForecasts:
    """Per scenario its P(shows); the scales' posterior weights and mean; and the dithers (for moves)."""

    p: dict[str, float]
    weights: np.ndarray
    scale: float
    dithers: dict[str, tuple[np.ndarray, np.ndarray] | None]  # at scale 1: rows and which showed (None: not kept)
    #: log P(the runs' outcomes | this forecast), the scale integrated out: how well it foresaw the day so far
    evidence: float = 0.0

    def to_dict(self) -> dict:
        return {
            "log_evidence": round(self.evidence, 3),
            "scales": list(SCALES),
            "weights": [round(float(w), 4) for w in self.weights],
            "scale": round(self.scale, 3),
            "contamination": CONTAMINATION,
            "draws": DRAWS,
        }


def _bias_draws(centre: dict[str, float], sd: dict[str, float], varied: list[str], n: int, seed: int) -> dict:
    rng = np.random.default_rng(seed + 7)
    out = {name: np.full(n, float(centre.get(name, NEUTRAL[name]))) for name in BIAS_NAMES}
    for name in varied:
        lo, hi = BIAS_LIMITS[name]
        out[name] = np.clip(out[name] + sd[name] * rng.standard_normal(n), lo, hi)
    return out


def forecast_sides(
    mission: Mission,
    targets: dict[str, Target],
    flown: list[tuple[str, bool]],
    sigma: np.ndarray,
    bias: tuple[dict[str, float], dict[str, float], list[str]],
    seed: int = 0,
    cache: dict | None = None,
) -> SideForecasts:
    """Each target scenario's P(shows its outcome), the noise's scale weighed by the runs ``flown`` so far
    (scenario, showed), each dithered run under a draw of ``bias`` (centre, s.d., the names drawn).

    ``cache`` (scenario -> its P per scale and dithers, or None for them; filled here) spares scenarios already
    drawn: the caller keeps one only while the mission, bias, noise and seed stay the same (the plan's water
    all afternoon: ``rapt-plan next`` keeps it in the day's record).
    """
    cache = {} if cache is None else cache
    todo = [s for s in targets if s not in cache]
    if todo:
        cache.update(_drawn(mission, {s: targets[s] for s in todo}, sigma, bias, seed))
    ids = list(targets)
    P = np.array([cache[s][0] for s in ids]).reshape(len(ids), len(SCALES))
    loglik = -0.5 * (np.log(SCALES) / SCALE_PRIOR_SD) ** 2
    row = {sid: i for i, sid in enumerate(ids)}
    for sid, showed in flown:
        if sid in row:
            p = P[row[sid]] if showed else 1.0 - P[row[sid]]
            loglik = loglik + np.log((1.0 - CONTAMINATION) * p + CONTAMINATION / 2)
    prior = -0.5 * (np.log(SCALES) / SCALE_PRIOR_SD) ** 2
    w = np.exp(loglik - loglik.max())
    evidence = float(loglik.max() + np.log(w.sum()) - (prior.max() + np.log(np.exp(prior - prior.max()).sum())))
    w /= w.sum()
    return SideForecasts(
        {sid: float(P[i] @ w) for i, sid in enumerate(ids)},
        w,
        float(np.exp(np.log(SCALES) @ w)),
        {s: cache[s][1] for s in ids},
        evidence,
    )


def _drawn(
    mission: Mission,
    targets: dict[str, Target],
    sigma: np.ndarray,
    bias: tuple[dict[str, float], dict[str, float], list[str]],
    seed: int,
) -> dict[str, tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]]:
    """Per scenario: P(shows) at each of :data:`SCALES` and its dithers at scale 1, all in a batch per scale."""
    ids = list(targets)
    U = np.array([targets[s].u for s in ids]).reshape(len(ids), -1)
    k = len(ids)
    draws = _bias_draws(*bias, DRAWS, seed)
    per_run = {name: np.tile(v, k) for name, v in draws.items()}
    P = np.zeros((k, len(SCALES)))
    dithers: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for g, scale in enumerate(SCALES):
        rows, r = dithered_runs(mission, U, DRAWS, np.asarray(sigma) * scale, seed, bias=per_run)
        scores, valid = r.scores.reshape(k, DRAWS, -1), r.valid.reshape(k, DRAWS)
        for i, sid in enumerate(ids):
            t = targets[sid]
            shows = valid[i] & np.all(scores[i][:, list(t.columns)] == np.asarray(t.values), axis=1)
            P[i, g] = float(shows[valid[i]].mean()) if valid[i].any() else 0.0
            if scale == 1.0:
                dithers[sid] = (rows[i], shows)
    return {sid: (P[i], dithers[sid]) for i, sid in enumerate(ids)}
