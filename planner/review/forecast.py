"""Predictions that say how sure they are: the day's runs forecast as mode probabilities, and scored.

Near a performance boundary a single deterministic prediction is a coin toss: the plan puts
its pairs there on purpose, and a bias known to five digits does not move a run that starts
a few metres or seconds off plan back to its side.  So ``rapt-plan compare`` also forecasts
each plan scenario as a distribution over the four modes (TF, SS, MS, TS), from seeded
Monte-Carlo runs (:func:`ensemble`):

* ``noise``: the execution noise alone (uncorrected): Gaussian unit-cube dithers flown with
  the simulator's stochastic effects on, exactly as the plan's dithering draws them
  (:func:`planner.common.execution_noise.dithered_runs`). Their sigma is the noise fitted to the
  day's runs (:mod:`planner.review.day_noise`: the spread of the logged tracks, timings and
  energy about the corrected replay, with ``plan.json``'s assumed ``study.dithering.sigma_u``
  as the prior); the corrected forecast under the assumed noise is drawn beside it, so the
  Brier scores show what fitting the noise changed (``corrected_assumed_noise``);
* ``bias_noise``: the same noise, each run also under a draw of the fitted execution bias
  (:func:`bias_draws`: the bias used at its centre, the parameters the logs identify drawn from
  the fit's posterior covariance, the others fixed, clipped to
  :data:`sim.uuv.bias.BIAS_LIMITS`).  Draw ``j`` has the same bias for every scenario, so the two
  sides of a pair move together as they do on one range day.

Both use the same seeds for the noise (common random numbers), so they differ only by the
bias.  The *corrected* forecast is ``bias_noise`` when the correction is used
(:mod:`planner.review.correction`), ``noise`` otherwise.

The day is scored by the Brier score (:func:`brier`): over every logged run with an end,
the mean of ``sum_mode (p_mode - observed_mode)^2`` (0 is perfect, 2 is confidently wrong;
a one-hot deterministic prediction scores 0 when right and 2 when wrong), and the binary
one for "the plan's predicted mode held" (:func:`brier_held`: the mean of ``(p - held)^2``,
``p`` the forecast's probability of the mode the plan predicted).  The reliability table
(:func:`reliability`) bins the corrected forecast's P(held) against the share that held.

A pair straddles with probability P(side a shows its outcome AND side b shows its) under the
corrected forecast, an outcome being the scenario's predicted mode and the values of its
pair's score elements as the plan predicted them (the plan's ``p_predicted``).  It is flagged
as no longer straddling when that probability is below :data:`STRADDLE_BELOW`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from planner.common.execution_noise import dithered_runs
from planner.common.plans import Plan
from planner.review.biasfit import BiasFit
from planner.review.runs import CompareConfig, Observation, PlanRuns
from rapt.errors import InputError
from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, Bias
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.scoring import MODE_NAMES

__all__ = [
    "STRADDLE_BELOW",
    "Ensemble",
    "plan_noise",
    "bias_draws",
    "ensemble",
    "brier",
    "brier_held",
    "one_hot",
    "run_forecast",
    "day_brier",
    "DayForecast",
    "forecast_day",
    "reliability",
    "RELIABILITY_BINS",
]

#: Forecast probabilities are binned this many ways for the reliability table (0-0.2, ..., 0.8-1).
RELIABILITY_BINS = 5

#: A pair whose probability of straddling (both sides showing their outcome) under the corrected
#: forecast is below this no longer straddles: an even chance is the least a run on the water is worth.
STRADDLE_BELOW = 0.5


def plan_noise(plan: Plan) -> np.ndarray:
    """The execution noise the plan was made with: a sigma per unit-cube coordinate (``study.dithering.sigma_u``)."""
    sigma = plan.data.get("study", {}).get("dithering", {}).get("sigma_u")
    if not isinstance(sigma, list) or len(sigma) != plan.mission.dim:
        raise InputError(
            f"PLAN: {plan.path} records no execution noise (study.dithering.sigma_u with {plan.mission.dim} "
            "values); regenerate the plan with rapt-plan generate"
        )
    return np.asarray(sigma, dtype=float)


def bias_draws(fit: BiasFit, centre: Bias, n: int, seed: int) -> dict[str, np.ndarray]:
    """``n`` biases around ``centre`` by parameter name, the first ``centre`` itself.

    Only the parameters the logs identify vary, jointly by the fit's posterior covariance
    (:attr:`rapt.mapfit.MapEstimate.covariance`); each is clipped to :data:`BIAS_LIMITS`.
    """
    out = {name: np.full(n, float(getattr(centre, name))) for name in BIAS_NAMES}
    est = fit.estimate
    varied = [name for name in est.names if est.identified.get(name, False)]
    cov = np.asarray(est.covariance, dtype=float)
    if n > 1 and varied and cov.shape == (len(varied), len(varied)):
        rng = np.random.default_rng(seed)
        z = rng.multivariate_normal(np.zeros(len(varied)), cov, size=n - 1, method="eigh")
        for i, name in enumerate(varied):
            lo, hi = BIAS_LIMITS[name]
            out[name][1:] = np.clip(out[name][1:] + z[:, i], lo, hi)
    return out


@dataclass
class Ensemble:
    """Monte-Carlo runs of some plan scenarios: per scenario ``n`` runs' scores, validity and modes."""

    ids: list[str]
    scores: np.ndarray  # (k, n, m)
    valid: np.ndarray  # (k, n)
    modes: np.ndarray  # (k, n), -1 where invalid

    def _row(self, sid: str) -> int:
        return self.ids.index(sid)

    def distribution(self, sid: str) -> np.ndarray | None:
        """P of each mode (:data:`MODE_NAMES` order) among the scenario's valid runs; None when none is valid."""
        k = self._row(sid)
        ok = self.valid[k]
        if not ok.any():
            return None
        return np.bincount(self.modes[k][ok], minlength=len(MODE_NAMES)) / ok.sum()

    def shows(self, sid: str, cols: Sequence[int], values: np.ndarray) -> np.ndarray:
        """Which runs of scenario ``sid`` are valid and show ``values`` on score columns ``cols``."""
        k = self._row(sid)
        return self.valid[k] & np.all(self.scores[k][:, list(cols)] == np.asarray(values), axis=1)

    def p_both(self, a: str, b: str, cols: Sequence[int], va: np.ndarray, vb: np.ndarray) -> dict:
        """P(a shows ``va`` AND b shows ``vb``) over the draws where both are valid (draw ``j`` of both
        sides shares its bias), and each side's own P."""
        both = self.valid[self._row(a)] & self.valid[self._row(b)]
        sa, sb = self.shows(a, cols, va), self.shows(b, cols, vb)
        if not both.any():
            return {"p_straddles": None, "p_sides": [None, None]}
        return {
            "p_straddles": float(np.mean((sa & sb)[both])),
            "p_sides": [float(np.mean(sa[both])), float(np.mean(sb[both]))],
        }


def ensemble(
    mission: Mission,
    ids: list[str],
    U: np.ndarray,
    sigma: np.ndarray,
    draws: int,
    seed: int,
    bias: Mapping[str, np.ndarray] | None = None,
    plant: Vehicle | None = None,
) -> Ensemble:
    """``draws`` runs of each row of ``U`` (named ``ids``) under the plan's execution noise ``sigma``, and with
    ``bias`` (arrays of ``draws`` biases by name, draw ``j`` flown in run ``j`` of every scenario) when given.

    Every forecast run goes through here: a bias the mission file sets for the day composes here.
    """
    U = np.atleast_2d(np.asarray(U, dtype=float))
    k = U.shape[0]
    per_run = None if bias is None else {name: np.tile(np.asarray(v, dtype=float), k) for name, v in bias.items()}
    _, r = dithered_runs(mission, U, draws, sigma, seed, bias=per_run, plant=plant)
    m = r.scores.shape[1]
    return Ensemble(
        list(ids), r.scores.reshape(k, draws, m), r.valid.reshape(k, draws), np.asarray(r.modes).reshape(k, draws)
    )


def one_hot(mode: str) -> np.ndarray:
    """A deterministic prediction as a forecast: probability 1 on its mode."""
    p = np.zeros(len(MODE_NAMES))
    p[MODE_NAMES.index(mode)] = 1.0
    return p


def brier(forecasts: Sequence[np.ndarray], observed: Sequence[str]) -> float | None:
    """Multi-class Brier score: the mean over runs of ``sum_mode (p_mode - [mode observed])^2``, in [0, 2]."""
    if not len(observed):
        return None
    return float(np.mean([np.sum((np.asarray(p) - one_hot(o)) ** 2) for p, o in zip(forecasts, observed)]))


def brier_held(p_held: Sequence[float], held: Sequence[bool]) -> float | None:
    """Binary Brier score of "the predicted mode held": the mean of ``(p - held)^2``, in [0, 1]."""
    if not len(held):
        return None
    return float(np.mean((np.asarray(p_held, dtype=float) - np.asarray(held, dtype=float)) ** 2))


def reliability(p_held: Sequence[float], held: Sequence[bool], bins: int = RELIABILITY_BINS) -> list[dict]:
    """Forecast P against observed frequency: per bin of P(the predicted mode held), the runs in it, their mean
    forecast and the share that held. A reliable forecast's rows lie on the diagonal (mean P = share held)."""
    p = np.asarray(p_held, dtype=float)
    h = np.asarray(held, dtype=bool)
    edges = np.linspace(0.0, 1.0, bins + 1)
    which = np.clip(np.digitize(p, edges[1:-1], right=False), 0, bins - 1)
    rows = []
    for b in range(bins):
        sel = which == b
        rows.append(
            {
                "p_low": float(edges[b]),
                "p_high": float(edges[b + 1]),
                "runs": int(sel.sum()),
                "mean_p": float(p[sel].mean()) if sel.any() else None,
                "held": float(h[sel].mean()) if sel.any() else None,
            }
        )
    return rows


def _mode_dict(p: np.ndarray | None) -> dict[str, float] | None:
    return None if p is None else {name: float(v) for name, v in zip(MODE_NAMES, p)}


def _p(p: np.ndarray | None, mode: str | None) -> float | None:
    return None if p is None or mode is None else float(p[MODE_NAMES.index(mode)])


def run_forecast(noise: Ensemble, biased: Ensemble, sid: str, observed: str | None, det: dict, used: bool) -> dict:
    """A logged run's forecast entry: the mode distributions, P(observed mode) and P(the plan's predicted
    mode) under each forecast; ``det`` holds the deterministic ``planned``, ``uncorrected`` and ``corrected`` modes."""
    dist = {"noise": noise.distribution(sid), "bias_noise": biased.distribution(sid)}
    dist["corrected"] = dist["bias_noise"] if used else dist["noise"]
    return {
        "deterministic": {"uncorrected": det["uncorrected"], "corrected": det["corrected"]},
        "modes": {k: _mode_dict(v) for k, v in dist.items() if k != "corrected"},
        "p_observed_mode": {k: _p(v, observed) for k, v in dist.items()},
        "p_predicted_mode": {k: _p(v, det["planned"]) for k, v in dist.items()},
        "runs_valid": {
            "noise": int(noise.valid[noise.ids.index(sid)].sum()),
            "bias_noise": int(biased.valid[biased.ids.index(sid)].sum()),
        },
    }


def day_brier(rows: list[dict], corrected_used: bool) -> dict:
    """The day's Brier scores (multi-class ``mode`` and binary ``held``) of each forecast, over the scenario
    rows with an observed mode and a forecast: ``deterministic_uncorrected`` (one-hot, as planned or on the
    calibrated vehicle), ``deterministic_corrected``, ``noise``, ``bias_noise`` and ``corrected`` (the one used)."""
    scored = _scored(rows)
    observed = [r["observed_mode"] for r in scored]
    held = [r["observed_mode"] == r["predicted_mode"] for r in scored]
    out: dict[str, dict] = {}
    for name, which in (("deterministic_uncorrected", "uncorrected"), ("deterministic_corrected", "corrected")):
        det = [r["forecast"]["deterministic"][which] for r in scored]
        fc = [one_hot(d) for d in det]
        out[name] = _scores(fc, observed, [float(d == r["predicted_mode"]) for d, r in zip(det, scored)], held)
    for name in ("noise", "bias_noise"):
        fc = [np.array([r["forecast"]["modes"][name][m] for m in MODE_NAMES]) for r in scored]
        out[name] = _scores(fc, observed, [r["forecast"]["p_predicted_mode"][name] for r in scored], held)
    out["corrected"] = dict(out["bias_noise" if corrected_used else "noise"])
    return {"runs": len(scored), **out}


def _scored(rows: list[dict]) -> list[dict]:
    """The scenario rows the day is scored on: an observed mode, and a forecast of both kinds."""
    return [
        r
        for r in rows
        if r["observed_mode"] is not None
        and None not in (r["forecast"]["modes"]["noise"], r["forecast"]["modes"]["bias_noise"])
    ]


def _scores(fc: list[np.ndarray], observed: list[str], p_held: Sequence[float], held: list[bool]) -> dict:
    return {"mode": brier(fc, observed), "held": brier_held([float(p) for p in p_held], held)}


@dataclass
class DayForecast:
    """The day's two forecasts of the plan scenarios flown or in a pair, and how they were drawn."""

    noise: Ensemble
    biased: Ensemble
    used: bool  # the correction is used: the corrected forecast is ``biased``
    draws: int
    seed: int
    sigma: np.ndarray
    varied: list[str]  # bias parameters drawn (the identified ones)
    centre: Bias
    #: the corrected forecast drawn with the plan's assumed noise instead of the day's (None: they are the same)
    assumed: Ensemble | None = None
    day_noise: dict | None = None  # planner.review.day_noise.DayNoise.to_dict()

    @property
    def corrected(self) -> Ensemble:
        return self.biased if self.used else self.noise

    def summary(self, rows: list[dict]) -> dict:
        """What ``comparison.json``'s ``forecast`` holds: how it was drawn, the noise fitted to the day, the day's
        Brier scores (the corrected forecast under the plan's assumed noise beside it) and the reliability table."""
        brier_rows = day_brier(rows, self.used)
        scored = _scored(rows)
        held = [r["observed_mode"] == r["predicted_mode"] for r in scored]
        p_corrected = [r["forecast"]["p_predicted_mode"]["corrected"] for r in scored]
        if self.assumed is not None:
            fc, observed, p_assumed, held_assumed = [], [], [], []
            for r, h in zip(scored, held):
                dist = self.assumed.distribution(r["id"])
                if dist is None:
                    continue
                fc.append(dist)
                observed.append(r["observed_mode"])
                p_assumed.append(float(dist[MODE_NAMES.index(r["predicted_mode"])]))
                held_assumed.append(h)
            brier_rows["corrected_assumed_noise"] = _scores(fc, observed, p_assumed, held_assumed)
        return {
            "draws": self.draws,
            "seed": self.seed,
            "noise_sigma_u": [float(v) for v in self.sigma],
            "day_noise": self.day_noise,
            "bias_centre": self.centre.to_dict(),
            "bias_varied": self.varied,
            "corrected_is": "bias_noise" if self.used else "noise",
            "straddle_below": STRADDLE_BELOW,
            "brier": brier_rows,
            "reliability": reliability(p_corrected, held),
        }


def forecast_day(
    plan: Plan,
    obs: list[Observation],
    runs: PlanRuns,
    fit: BiasFit,
    used: bool,
    cfg: CompareConfig,
    day_noise=None,
) -> DayForecast:
    """Both forecasts (module docstring) of every scenario flown or in a pair, ``cfg.draws`` runs each,
    seeded by ``cfg.seed``, with the calibrated vehicle when there is one.

    ``day_noise`` (:class:`planner.review.day_noise.DayNoise`): the noise fitted to the day's runs, which the
    forecasts are then drawn with; the corrected forecast under the plan's assumed noise is drawn beside them
    (``assumed``), so the day's Brier scores show what fitting the noise changed. None: the plan's noise.
    """
    if cfg.draws < 1:
        raise InputError(f"--draws: expected a number of runs >= 1, got {cfg.draws}")
    wanted = {o.sid for o in obs} | {s for pair in plan.pairs for s in pair["scenarios"]}
    ids = [sid for sid in runs.ids if sid in wanted]
    U = runs.U[[runs.row_of[sid] for sid in ids]]
    assumed_sigma = plan_noise(plan)
    sigma = assumed_sigma if day_noise is None else np.asarray(day_noise.sigma_u, dtype=float)
    m = plan.mission
    noise = ensemble(m, ids, U, sigma, cfg.draws, cfg.seed, plant=cfg.plant)
    draws = bias_draws(fit, fit.bias, cfg.draws, cfg.seed)
    biased = ensemble(m, ids, U, sigma, cfg.draws, cfg.seed, bias=draws, plant=cfg.plant)
    varied = [n for n in BIAS_NAMES if np.ptp(draws[n]) > 0]
    assumed = None
    if not np.array_equal(sigma, assumed_sigma):
        assumed = ensemble(m, ids, U, assumed_sigma, cfg.draws, cfg.seed, bias=draws if used else None, plant=cfg.plant)
    record = None if day_noise is None else day_noise.to_dict()
    return DayForecast(noise, biased, used, cfg.draws, cfg.seed, sigma, varied, fit.bias, assumed, record)
