"""The day's execution noise, measured: how far the logged runs spread about the corrected replay.

The plan dithers its scenarios by an *assumed* execution noise (``--dither-sigma``, by
default 10 m on positions, 30 s on times, 1 % on the charge). On the day the logs show how
far this vehicle, in this water, actually strays from what the corrected model predicts for
it. A forecast spread by the assumption alone is under-confident on a day that was
calmer than assumed and over-confident on a rougher one. :func:`fit_day_noise` estimates
each kind of noise from the day's counted runs against their corrected replays:

- **position** (m, per coordinate): the horizontal distance from each logged position to the
  corrected replay's *path* (its nearest point, whenever the replay passed there): the
  across-path component of a deviation, one coordinate's worth, so for a per-axis sigma
  ``s`` each run gives ``mean(d^2)``.  The path, not the replay's position at the same time: a vehicle that
  flies the predicted path a minute late is off in time, not in position, and the position
  noise the plan dithers by moves the scenario's places (starts, no-go areas), which only a
  departure from the path can cross; a time-matched distance counts every along-track slip
  as position;
- **time** (s): the difference between the run's logged end and its replay's, over runs that
  both end at the recovery point (a run the pack's limit or a collision ends, ends when the
  model runs out, not on the schedule);
- **battery** (% of the pack): the energy drawn by the common end of the two tracks, logged
  against replayed, as a share of the pack.

The plan's assumed noise is the prior: a scaled-inverse-chi-squared with ``prior_weight``
pseudo-runs at the assumed sigma, so ``s^2 = (w s0^2 + sum v_i) / (w + n)``. With no run of a
kind the prior stands. The per-coordinate sigma of the forecast is the plan's ``sigma_u``
scaled kind by kind by ``s / s0``, each kept within :data:`MAX_SIGMA_SHARE` of its range as
the plan's are. A plan made with one unit-cube sigma has no physical prior to scale; its
noise is kept, and the record says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from planner.common.execution_noise import NOISE_KINDS, coordinate_kinds
from planner.common.plans import Plan
from planner.review.daybias import with_table
from planner.review.runs import Observation, PlanRuns
from sim.uuv.interface import HJ_PER_WH
from sim.uuv.mission import Vehicle
from sim.uuv.missionnoise import SECTION, ExecutionNoise, execution_noise_table

__all__ = [
    "PRIOR_WEIGHT",
    "MAX_SIGMA_SHARE",
    "DayNoise",
    "fit_day_noise",
    "noise_from_comparison",
    "with_execution_noise",
]

#: Pseudo-runs the plan's assumed noise counts for: two runs of the day weigh as much as the assumption.
PRIOR_WEIGHT = 2.0
#: A sigma at most this share of a parameter's range, as the plan's dithering allows (planner.plan.dithering).
MAX_SIGMA_SHARE = 0.25


@dataclass
class DayNoise:
    """The prior and fitted execution noise by kind, the runs behind each, and the forecast's sigma per coordinate."""

    prior: dict[str, float]
    fitted: dict[str, float]
    runs: dict[str, int]
    observed_rms: dict[str, float | None]
    sigma_u: np.ndarray
    prior_sigma_u: np.ndarray
    note: str = ""
    prior_weight: float = PRIOR_WEIGHT
    per_run: list[dict] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "prior": self.prior,
            "fitted": self.fitted,
            "units": dict(NOISE_KINDS),
            "runs": self.runs,
            "observed_rms": self.observed_rms,
            "prior_weight": self.prior_weight,
            "sigma_u": [float(v) for v in self.sigma_u],
            "prior_sigma_u": [float(v) for v in self.prior_sigma_u],
            "note": self.note,
            "per_run": self.per_run,
        }


#: Spacing (m) at which a replayed path is sampled for the nearest-point distance (error at most half of it).
PATH_SPACING_M = 1.0


def path_distance(points: np.ndarray, path: np.ndarray) -> np.ndarray:
    """Each of ``points`` (k, 2)'s distance (m) to the polyline ``path`` (m, 2), sampled every :data:`PATH_SPACING_M`."""
    legs = np.diff(path, axis=0)
    counts = np.ceil(np.hypot(legs[:, 0], legs[:, 1]) / PATH_SPACING_M).astype(np.int64)
    leg = np.repeat(np.arange(legs.shape[0]), counts)
    within = np.arange(leg.size) - np.repeat(np.cumsum(counts) - counts, counts)  # 0 .. count - 1 along each leg
    samples = path[leg] + ((within + 1) / counts[leg])[:, None] * legs[leg]
    distance, _ = cKDTree(np.concatenate([path[:1], samples])).query(points)
    return np.asarray(distance, dtype=float)


def _residuals(obs: list[Observation], runs: PlanRuns, capacity_wh: float) -> tuple[dict[str, list[float]], list[dict]]:
    """Per kind, each run's squared residual against its corrected replay (position per axis); and per run, the
    residuals themselves for the record."""
    out: dict[str, list[float]] = {kind: [] for kind in NOISE_KINDS}
    per_run = []
    for o in obs:
        replay = runs.corr.trajectory(runs.row_of[o.sid])
        track = o.run.track
        if replay is None or track.shape[0] < 2:
            continue
        n = min(track.shape[0], replay.shape[0])
        predicted = track[:, 0] <= replay[-1, 0]  # a log that outlasts its replay is not predicted past its end
        d2 = path_distance(track[predicted, 1:3], replay[:, 1:3]) ** 2
        row: dict = {"log": o.run.path.name, "scenario": o.sid, "position_m": float(math.sqrt(np.mean(d2)))}
        out["position"].append(float(np.mean(d2)))
        drawn = (track[n - 1, 4] - replay[n - 1, 4]) / HJ_PER_WH / capacity_wh * 100.0
        if np.isfinite(drawn):
            out["battery"].append(float(drawn**2))
            row["battery_pct"] = float(drawn)
        if _recovered_in_both(o, runs):
            late = float(track[-1, 0] - replay[-1, 0])
            out["time"].append(late**2)
            row["time_s"] = late
        per_run.append(row)
    return out, per_run


def _recovered_in_both(o: Observation, runs: PlanRuns) -> bool:
    """The run and its replay both ended at the recovery point: then the end times differ by the schedule's slip.
    A run that ends otherwise (the pack's limit, a collision) ends when the model runs out, not on a timing."""
    names = runs.corr.names
    if o.scores is None or not o.run.has_end or "recovery" not in names:
        return False
    c = names.index("recovery")
    return bool(o.scores[c] == 1 and runs.corr.scores[runs.row_of[o.sid], c] == 1)


def fit_day_noise(
    plan: Plan,
    obs: list[Observation],
    runs: PlanRuns,
    prior_sigma_u: np.ndarray,
    plant: Vehicle | None = None,
    prior_weight: float = PRIOR_WEIGHT,
) -> DayNoise:
    """The day's noise from ``obs`` (the counted runs) against their corrected replays in ``runs`` (module docstring)."""
    m = plan.mission
    expected = dict(plan.data.get("study", {}).get("dithering", {}).get("expected") or {})
    prior_sigma_u = np.asarray(prior_sigma_u, dtype=float)
    if "unit" in expected or not all(k in expected for k in NOISE_KINDS):
        empty: dict[str, float | None] = {k: None for k in NOISE_KINDS}
        return DayNoise(
            {}, {}, {k: 0 for k in NOISE_KINDS}, empty, prior_sigma_u.copy(), prior_sigma_u,
            note="the plan's noise is one unit-cube sigma, with no physical prior to fit: kept as planned",
        )  # fmt: skip
    vehicle = plant or m.vehicle
    squares, per_run = _residuals(obs, runs, float(vehicle.battery_wh))
    fitted, counts, rms = {}, {}, {}
    for kind in NOISE_KINDS:
        s0 = float(expected[kind])
        v = squares[kind]
        counts[kind] = len(v)
        rms[kind] = float(math.sqrt(np.mean(v))) if v else None
        fitted[kind] = float(math.sqrt((prior_weight * s0**2 + sum(v)) / (prior_weight + len(v))))
    kinds = coordinate_kinds(m)
    sigma = prior_sigma_u.copy()
    for c, coord_kind in enumerate(kinds):
        if coord_kind is not None and expected[coord_kind] > 0:
            scale = fitted[coord_kind] / float(expected[coord_kind])
            sigma[c] = min(prior_sigma_u[c] * scale, MAX_SIGMA_SHARE)
    note = "; ".join(
        f"{kind} {expected[kind]:g} -> {fitted[kind]:.3g} {unit} from {counts[kind]} run(s)"
        for kind, unit in NOISE_KINDS.items()
    )
    return DayNoise(
        {k: float(expected[k]) for k in NOISE_KINDS}, fitted, counts, rms, sigma, prior_sigma_u, note,
        prior_weight, per_run,
    )  # fmt: skip


def noise_from_comparison(data: dict) -> ExecutionNoise | None:
    """The day's fitted noise of a ``comparison.json`` (``forecast.day_noise``) as a mission file's
    ``[execution_noise]``; None when the comparison fitted none (an older one, or a unit-cube plan noise)."""
    record = (data.get("forecast") or {}).get("day_noise") or {}
    fitted = record.get("fitted") or {}
    if not all(isinstance(fitted.get(k), (int, float)) and fitted[k] > 0 for k in NOISE_KINDS):
        return None
    plan = data.get("plan") or {}
    runs = record.get("runs") or {}
    source = (
        f"rapt-plan compare of plan {plan.get('id', '?')}: "
        + ", ".join(f"{k} from {runs.get(k, 0)} run(s)" for k in NOISE_KINDS)
        + f", the plan's assumption as a prior of {record.get('prior_weight', PRIOR_WEIGHT):g} runs"
    )
    return ExecutionNoise(float(fitted["position"]), float(fitted["time"]), float(fitted["battery"]), source)


def with_execution_noise(text: str, noise: ExecutionNoise) -> str:
    """Mission-file ``text`` with its ``[execution_noise]`` table (if any) replaced by ``noise``'s, at the end."""
    return with_table(text, SECTION, execution_noise_table(noise))
