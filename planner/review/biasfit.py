"""Estimate the execution bias (:mod:`sim.uuv.bias`) from logged runs, with what the logs can tell.

Each run is cut into short open-loop segments replayed on the logged set-points through
the simulator's own vehicle and tide models (:mod:`planner.review.segments`), and the six bias
parameters are fitted to the logged positions and energy used: a maximum a posteriori
estimate (:func:`rapt.mapfit.fit_map`) under :data:`PRIORS`, one documented prior per
parameter centred on neutral with a width a range engineer would accept.  A parameter
whose posterior is not clearly narrower than its prior is *not identified*: the logs
cannot tell it (one run, one tide phase: a tide-table error against a clock error), so
it stays neutral for prediction and is reported so.

The standard errors must hold when the residuals are not independent: a real vehicle's
navigation drift or an unmodelled current moves a whole segment, and the segments of a
run together.  The reported s.e. is the largest of the Laplace, the cluster-robust and a
resampling estimate: with :data:`BOOTSTRAP_BY_RUN_FROM` runs or more, a delete-one-run
jackknife (runs are the independent draws; a bootstrap over a dozen of them is
optimistic); with fewer, a block bootstrap over consecutive segments.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

import sim.uuv
from planner.review.segments import SEGMENT_STEPS, Segments, replay, segment_batch
from rapt.errors import InputError
from rapt.mapfit import MapEstimate, Prior, fit_map
from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, NEUTRAL, Bias
from sim.uuv.mission import Mission, Vehicle

__all__ = ["BiasFit", "fit_bias", "PRIORS", "bias_priors"]

#: Residual units: metres of position, watt-hours of energy used.
SIGMA_POSITION_M = 1.0
SIGMA_ENERGY_WH = 0.05
#: One standard deviation of each parameter's prior, around neutral: what a range day's
#: vehicle and tide table plausibly get wrong (a speed loop 15 % off, a tide table 30 %
#: or 0.3 m/s off, a compass 5 degrees off, a battery gauge 15 % off, a tidal file half
#: an hour off).  Larger biases are still found when the logs show them clearly.
PRIOR_SD = {
    "speed": 0.15,
    "current_scale": 0.3,
    "current_offset": 0.3,
    "current_cross": 0.3,
    "heading": 5.0,
    "battery": 0.15,
    "start_time": 1800.0,
}
#: Runs needed before the bootstrap resamples whole runs rather than blocks of segments.
BOOTSTRAP_BY_RUN_FROM = 6
#: Consecutive segments per bootstrap block when there are too few runs.
SEGMENTS_PER_BLOCK = 3
#: Bootstrap refits (0: analytic standard errors only).
BOOTSTRAP = 20


def bias_priors(names: tuple[str, ...] = BIAS_NAMES) -> list[Prior]:
    """The priors of ``names`` (:data:`PRIOR_SD` around neutral, within :data:`sim.uuv.bias.BIAS_LIMITS`)."""
    return [Prior(n, NEUTRAL[n], PRIOR_SD[n], *BIAS_LIMITS[n]) for n in names]


PRIORS = {p.name: p for p in bias_priors()}


@dataclass
class BiasFit:
    """The fitted bias (unidentified parameters at neutral) with the fit behind it."""

    bias: Bias
    estimate: MapEstimate  # per parameter: MAP value, posterior s.e., identified
    rms_position_m: float
    rms_energy_wh: float
    rms_position_neutral_m: float
    segments: int
    residuals: int
    runs: int
    fitted: tuple[str, ...] = BIAS_NAMES
    end_conditions: dict = field(default_factory=dict)  # how the closed-loop check used the runs' ends

    @property
    def stderr(self) -> dict[str, float]:
        return {n: self.estimate.stderr.get(n, 0.0) for n in BIAS_NAMES}

    @property
    def identified(self) -> dict[str, bool]:
        return {n: self.estimate.identified.get(n, False) for n in BIAS_NAMES}

    @property
    def success(self) -> bool:
        return self.estimate.success

    @property
    def message(self) -> str:
        return self.estimate.message

    @property
    def correlation(self) -> dict[str, dict[str, float]]:
        return self.estimate.correlation

    def with_bias(self, bias: Bias, end_conditions: dict) -> BiasFit:
        """The same fit with the bias chosen by the closed-loop check of the runs' ends."""
        return BiasFit(
            bias,
            self.estimate,
            self.rms_position_m,
            self.rms_energy_wh,
            self.rms_position_neutral_m,
            self.segments,
            self.residuals,
            self.runs,
            self.fitted,
            end_conditions,
        )

    def to_dict(self) -> dict:
        """Per parameter: the estimate used for prediction, its s.e., whether the logs identify it, its prior."""
        out = {}
        for n in BIAS_NAMES:
            fitted = n in self.fitted
            out[n] = {
                "estimate": float(getattr(self.bias, n)),
                "stderr": self.estimate.stderr[n] if fitted else 0.0,
                "identified": bool(fitted and self.estimate.identified[n]),
                "map_estimate": self.estimate.map_value[n] if fitted else NEUTRAL[n],
                "prior": {"centre": PRIORS[n].centre, "sd": PRIORS[n].sd} if fitted else None,
            }
        return out


def _residuals(mission: Mission, seg: Segments, bias: Bias, vehicle: Vehicle | None = None) -> np.ndarray:
    px, py, pe, _ = replay(mission, seg, bias, vehicle)
    v = seg.valid
    dx = (px - seg.obs_x)[v] / SIGMA_POSITION_M
    dy = (py - seg.obs_y)[v] / SIGMA_POSITION_M
    de = (pe - seg.obs_energy_wh)[v] / SIGMA_ENERGY_WH
    return np.concatenate([dx, dy, de])


def bootstrap_blocks(seg: Segments) -> np.ndarray:
    """The bootstrap block of every segment: its run when there are :data:`BOOTSTRAP_BY_RUN_FROM` runs
    or more, else runs of :data:`SEGMENTS_PER_BLOCK` consecutive segments of one run."""
    runs = seg.run
    if len(set(runs.tolist())) >= BOOTSTRAP_BY_RUN_FROM:
        return runs.copy()
    block = np.zeros(runs.size, dtype=np.int64)
    nxt, last_run, count = -1, None, 0
    for j, r in enumerate(runs.tolist()):
        if r != last_run or count == SEGMENTS_PER_BLOCK:
            nxt, last_run, count = nxt + 1, r, 0
        block[j] = nxt
        count += 1
    return block


def fit_bias(
    mission: Mission,
    runs: list,
    start_times: list[float],
    fit: tuple[str, ...] = BIAS_NAMES,
    length: int = SEGMENT_STEPS,
    bootstrap: int = BOOTSTRAP,
    seed: int = 0,
    vehicle: Vehicle | None = None,
    priors: dict[str, tuple[float, float]] | None = None,
) -> BiasFit:
    """MAP fit of the parameters ``fit`` (the others stay neutral) to all ``runs`` jointly.

    ``vehicle`` (default the mission's) is the vehicle model the segments are replayed with:
    a calibrated one (:mod:`planner.review.calibrate`) leaves the bias only what calibration did not explain.
    ``priors`` (centre, sd by name) replace :data:`PRIORS` where given: the posterior of earlier logs, so a
    day's fit is updated log by log (``rapt-plan next``).
    """
    seg = segment_batch(mission, runs, start_times, length)
    if not seg.valid.any():
        raise InputError(
            "LOGS: no replayable flight in the logs (no telemetry steps with set-points); the bias cannot be estimated"
        )
    names = tuple(n for n in BIAS_NAMES if n in fit)

    def bias_of(theta: np.ndarray) -> Bias:
        return Bias(**{n: float(v) for n, v in zip(names, theta)})

    per_segment = np.nonzero(seg.valid)[0]
    blocks = bootstrap_blocks(seg)[per_segment]
    groups = np.concatenate([blocks, blocks, blocks])
    by_run = len(set(seg.run.tolist())) >= BOOTSTRAP_BY_RUN_FROM
    tiled: dict[int, Segments] = {}

    def residuals_many(thetas: np.ndarray) -> np.ndarray:
        """Residuals of several biases in one replay: the segments repeated once per bias."""
        p, n = thetas.shape[0], seg.valid.shape[0]
        if p not in tiled:
            tiled[p] = seg.repeated(p)
        values = {name: np.full(n * p, NEUTRAL[name]) for name in BIAS_NAMES}
        for i, name in enumerate(names):
            values[name] = np.repeat(thetas[:, i], n)
        r = _residuals(mission, tiled[p], SimpleNamespace(**values), vehicle)  # type: ignore[arg-type]
        k = int(seg.valid.sum())
        parts = r.reshape(3, p, k)  # dx, dy, de, each in segment order within each copy
        return parts.transpose(1, 0, 2).reshape(p, 3 * k)

    chosen = [
        Prior(p.name, *priors[p.name], p.low, p.high) if priors and p.name in priors else p for p in bias_priors(names)
    ]
    est = fit_map(
        lambda th: _residuals(mission, seg, bias_of(th), vehicle),
        chosen,
        residuals_many=residuals_many,
        groups=groups,
        jackknife=by_run and bootstrap > 0,
        kinds=np.repeat(np.array(["position", "position", "energy"]), per_segment.size),
        bootstrap=bootstrap,
        seed=seed,
    )
    best = bias_of(np.array([est.value[n] for n in names]))
    r = _residuals(mission, seg, best, vehicle)
    r0 = _residuals(mission, seg, Bias(), vehicle)
    k = int(seg.valid.sum())
    return BiasFit(
        best,
        est,
        float(np.sqrt(np.mean(r[:k] ** 2 + r[k : 2 * k] ** 2))) * SIGMA_POSITION_M,
        float(np.sqrt(np.mean(r[2 * k :] ** 2))) * SIGMA_ENERGY_WH,
        float(np.sqrt(np.mean(r0[:k] ** 2 + r0[k : 2 * k] ** 2))) * SIGMA_POSITION_M,
        int(seg.valid.shape[0]),
        int(r.size),
        int(len(set(seg.run.tolist()))),
        names,
    )


#: How far a re-simulated run may end from the logged end before it counts against a bias (s).
END_TIME_SD_S = 60.0
#: Log-likelihood lost when a re-simulated run ends in another condition than the logged one
#: (a fuel return instead of a completed mission, a collision, a missed window): as unlikely
#: as an end time four standard deviations off.
END_MISMATCH_LOGLIK = -8.0
#: Posterior draws tried against the logged ends, besides the estimate itself.
END_CANDIDATES = 16
#: Log-likelihood by which a posterior draw must beat the estimate when it reproduces no more ends.
DRAW_MARGIN = 2.0
#: Score columns that make a run's end condition.
END_COLUMNS = ("mission.return_reason", "collisions", "transmission", "recovery", "mission_success")


def end_condition_loglik(names: list[str], simulated: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """Log-likelihood of each observed end under each simulated run: (k, n) from (k, n, m) and (n, m)."""
    cols = [names.index(c) for c in END_COLUMNS if c in names]
    t = names.index("mission.time_s")
    same = np.all(np.isclose(simulated[..., cols], observed[None, :, cols], equal_nan=True), axis=-1)
    dt = (simulated[..., t] - observed[None, :, t]) / END_TIME_SD_S
    return np.where(same, -0.5 * np.nan_to_num(dt, nan=0.0) ** 2, END_MISMATCH_LOGLIK)


def check_end_conditions(
    mission: Mission,
    fit: BiasFit,
    runs: list,
    start_times: list[float],
    U: np.ndarray,
    observed: list[np.ndarray | None],
    *,
    candidates: int = END_CANDIDATES,
    seed: int = 0,
    length: int = SEGMENT_STEPS,
    vehicle: Vehicle | None = None,
) -> BiasFit:
    """The fit with its bias chosen, among the estimate and ``candidates`` posterior draws, by the
    segments' posterior times the likelihood of the logged end conditions (``observed``: each run's
    scores from its log, None when its end is not in the log) under a closed-loop re-simulation.

    The segments see how the vehicle moves; only a closed-loop run sees where a decision falls
    (the fuel return, the transmission window, a collision).  With exact logs the segments
    dominate and the estimate stands; with noisy ones, a draw that also reproduces how the runs
    ended is preferred.
    """
    ended = [k for k, s in enumerate(observed) if s is not None]
    names = [n for n in BIAS_NAMES if n in fit.fitted]
    if not ended or not any(fit.identified[n] for n in names):
        return fit.with_bias(fit.bias, {"logs_with_end": len(ended), "candidates": 0, "chosen": "estimate"})
    draws = fit.estimate.draws(candidates, seed)
    thetas = np.vstack([fit.estimate.vector()[None, :], draws])
    biases = [Bias(**{n: float(v) for n, v in zip(names, th)}) for th in thetas]
    Ue = np.asarray(U, dtype=float)[ended]
    r = sim.uuv.simulate(mission, np.tile(Ue, (len(biases), 1)), bias=[b for b in biases for _ in ended], plant=vehicle)
    sims = r.scores.reshape(len(biases), len(ended), -1)
    obs = np.array([observed[k] for k in ended])
    end_ll = end_condition_loglik(r.names, sims, obs).sum(axis=1)
    seg = segment_batch(mission, runs, start_times, length)
    per_segment = np.nonzero(seg.valid)[0].size
    kind_scale = np.repeat(
        [
            fit.estimate.noise_scale.get("position", 1.0),
            fit.estimate.noise_scale.get("position", 1.0),
            fit.estimate.noise_scale.get("energy", 1.0),
        ],
        per_segment,
    )
    prior = np.array([[(th[i] - PRIORS[n].centre) / PRIORS[n].sd for i, n in enumerate(names)] for th in thetas])
    seg_ll = np.array([-0.5 * np.sum((_residuals(mission, seg, b, vehicle) / kind_scale) ** 2) for b in biases])
    seg_ll -= 0.5 * np.sum(prior**2, axis=1)
    total = seg_ll + end_ll
    best = int(np.argmax(total))
    agree = end_condition_loglik(r.names, sims, obs) > END_MISMATCH_LOGLIK
    if agree[best].sum() <= agree[0].sum() and total[best] - total[0] < DRAW_MARGIN:
        best = 0  # a draw must earn its place over the estimate
    return fit.with_bias(
        biases[best],
        {
            "logs_with_end": len(ended),
            "candidates": len(biases),
            "chosen": "estimate" if best == 0 else "posterior draw",
            "ends_reproduced_by_estimate": int(agree[0].sum()),
            "ends_reproduced_by_chosen": int(agree[best].sum()),
            "end_time_sd_s": END_TIME_SD_S,
        },
    )
