"""The vehicle fit behind ``rapt-plan calibrate``: a mission's ``[vehicle]`` block fitted to logged runs.

A vehicle whose dynamics differ from the mission file's (a real vehicle, another vehicle
model) shows steady differences that no execution bias (:mod:`sim.uuv.bias`) describes:
the speed it reaches per commanded speed, how fast it turns, how much energy a metre
costs.  :func:`fit_vehicle` fits the observable properties of the ``[vehicle]`` block
(:data:`FITTED`) to logs flown by any autonomy:

- every log is cut into short open-loop segments replayed on the logged set-points from
  the logged state (:mod:`planner.review.segments`), so no autonomy decision sits inside a
  prediction and the fit is smooth in the parameters;
- the residuals are the predicted minus logged positions (:data:`SIGMA_POSITION_M`),
  headings (wrapped, :data:`SIGMA_HEADING_DEG`) and energy used (:data:`SIGMA_ENERGY_WH`),
  each kind weighted by its own robust noise scale, so a precise kind is not drowned by
  a noisy one;
- the estimate is the maximum a posteriori fit of :func:`rapt.mapfit.fit_map` under one
  prior per property centred on the file's value, :data:`PRIOR_SHARE` of it wide (what a
  test engineer would accept a datasheet to be off by), with standard errors that hold
  when a run's residuals move together (cluster-robust and a block bootstrap by run,
  :func:`planner.review.biasfit.bootstrap_blocks`), plus, for vehicle-paced runs, the replay's
  own approximation (:data:`MODEL_SHARE_PACED`);
- the ascent rate leaves no trace in positions and energy: it is timed from each surface
  command to the first report that says surfaced
  (:func:`planner.review.calibration_legs.fit_ascent`);
- a property is identified when its posterior s.d. is below half its prior's (that rule
  alone); one the logs do not identify (``max_speed`` when no command asked for more than
  the vehicle reaches, the power exponent with speed legs at fewer than 3 speeds) keeps
  the file's value and is named with the leg that would identify it
  (:data:`planner.review.calibration_legs.NEEDS`);
- a calibration run's log (its record lists legs) is enough alone, and it adds two terms
  (:mod:`planner.review.calibration_terms`): a measured speed curve in place of
  ``speed_gain`` and ``max_speed`` when its straight legs span enough commanded speeds, and
  the current it flew in, so the vehicle is not fitted to water that was not there;
  if a field is left
  unidentified because a leg that identifies it was cut short (the watchdog or a pilot
  took over, or the log ended), nothing is written unless the caller keeps those fields
  at the file's values.

Not fitted, and why: ``cruise_speed`` is what the autonomy commands (a choice, not a
property of the vehicle; ``speed_gain`` carries what the vehicle makes of it);
``battery_wh``, ``start_battery``, ``reserve_factor`` and ``critical_battery`` are the
range's and the autonomy's settings, not seen in a track; the sonar and navigation noise
(``sonar_*``, ``ins_drift_m_per_s``, ``gps_sigma_m``) and ``sway_damping`` leave no
steady trace in position and energy a few minutes long.  The tide and the clock are taken
as the mission file says: fit an execution bias with ``rapt-plan compare`` for those.

The command that reads the logs and writes the calibrated file is :mod:`planner.review.calibrate`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from planner.review.biasfit import bootstrap_blocks
from planner.review.calibration_legs import (
    LEG_KINDS,
    NEEDS,
    AscentFit,
    CutLeg,
    ascent_prior,
    fit_ascent,
    is_calibration_log,
    with_ascent,
    with_independent,
    without_terms,
)
from planner.review.calibration_terms import (
    CURVE_MIN_SPEEDS,
    POWER_TERMS,
    SURFACE_TERMS,
    fit_curve,
    fit_power,
    is_water,
    knot_command,
    knot_name,
    leg_power_points,
    monotone_curve,
    power_curve_fits,
    surface_prior,
    surface_values,
    term_need,
    term_prior,
    term_unit,
    term_value,
    water_terms,
    with_surface,
    with_terms,
)
from planner.review.daybias import DayWater, water_record
from planner.review.pack import PackReading
from planner.review.segment_fit import (
    SIGMA_ENERGY_WH,
    SIGMA_HEADING_DEG,
    SIGMA_POSITION_M,
    SLOW_TERMS,
    TURN_TERMS,
    SegmentSolver,
    choose_loop,
    residual_parts,
    rms_of,
)
from planner.review.segments import SEGMENT_STEPS, segment_batch
from rapt.errors import InputError
from rapt.mapfit import IDENTIFIED_BELOW, MapEstimate, Prior
from sim.uuv.bias import Bias
from sim.uuv.mission import Mission, Vehicle

__all__ = [
    "Calibration",
    "fit_vehicle",
    "vehicle_priors",
    "FITTED",
    "UNITS",
    "MIN_LOGS",
    "CALIBRATION_SCHEMA",
]

CALIBRATION_SCHEMA = "rapt.calibration/1"

#: The ``[vehicle]`` fields fitted, in this order.
FITTED: tuple[str, ...] = (
    "speed_gain",
    "max_speed",
    "surge_time_constant_s",
    "max_turn_rate_dps",
    "yaw_time_constant_s",
    "heading_time_s",
    "hotel_w",
    "drag_w",
    "power_exponent",
    "slow_share",
    "slow_time_constant_s",
    "ascent_rate_mps",
    "surface_max_speed",
    "surface_power_w",
)
#: Those fitted to the segment replay's positions, headings and energy (the ascent rate is timed instead:
#: :func:`planner.review.calibration_legs.fit_ascent`; the surface terms measured on the surfaced
#: steps: :func:`planner.review.calibration_terms.fit_surface`).
SEGMENT_FITTED: tuple[str, ...] = FITTED[:-3]
UNITS = {
    "speed_gain": "x",
    "max_speed": "m/s",
    "surge_time_constant_s": "s",
    "max_turn_rate_dps": "deg/s",
    "yaw_time_constant_s": "s",
    "heading_time_s": "s",
    "hotel_w": "W",
    "drag_w": "W",
    "power_exponent": "x",
    "slow_share": "x",
    "slow_time_constant_s": "s",
    "ascent_rate_mps": "m/s",
    "surface_max_speed": "m/s",
    "surface_power_w": "W",
}
#: Fewest plan-run logs a calibration takes.  One run's segments share one tide phase, one
#: route and one navigation drift, so its errors cannot be told from the vehicle's; a second,
#: independent run is the least that lets the standard errors (which resample runs or
#: blocks of segments) see how much the estimate moves from run to run.  A calibration
#: run's log (its scenario record lists legs at several speeds, turns, a hold and an
#: ascent: :func:`planner.review.calibration_legs.is_calibration_log`) is enough alone: its
#: legs separate what one plan run confounds, and its standard errors resample its blocks.
MIN_LOGS = 2
#: Prior s.d. as a share of the file's value: a datasheet or an earlier calibration
#: that is 30 % off is what a test engineer would still accept; larger errors are found
#: when the logs show them clearly.
PRIOR_SHARE = 0.3
#: Smallest prior s.d. per field (a file value of 0 still gets a usable prior).
PRIOR_SD_FLOOR = {
    "speed_gain": 0.05,
    "max_speed": 0.1,
    "surge_time_constant_s": 0.3,
    "max_turn_rate_dps": 1.0,
    "yaw_time_constant_s": 0.3,
    "heading_time_s": 0.3,
    "hotel_w": 5.0,
    "drag_w": 10.0,
    "power_exponent": 0.3,
    "slow_share": 0.3,
    "slow_time_constant_s": 10.0,
}
#: Largest slow share the fit considers: a loop that answers almost wholly slowly is no vector loop.
SLOW_SHARE_HIGH = 0.9

#: The fitted time constants (s): a thruster vehicle's may be a twentieth of a torpedo's.
TIME_CONSTANTS = ("surge_time_constant_s", "yaw_time_constant_s", "heading_time_s")
#: The power exponent's range (the mission file's rule): 0.5 (flatter than a thruster's) to 4.
EXPONENT_RANGE = (0.5, 4.0)
#: Upper bound of the power terms (W): the logs decide within it, however far from the file.
POWER_HIGH_W = 20000.0
#: Share of a value added (in quadrature) to its standard error when vehicle-paced runs are
#: fitted: the replay's own approximation of a continuously moving vehicle (sub-steps,
#: heading and energy reports a fraction of a second older than the position) biases the
#: estimates by up to about this much on the bare-autopilot front-seat, which the
#: statistical standard errors do not see.
MODEL_SHARE_PACED = 0.03
#: Share of a power term added (in quadrature) to its standard error when measured on a calibration
#: run's settled legs: a leg's mean power is the power at its mean speed only to about this much.
LEG_POWER_SHARE = 0.02
#: Bootstrap refits for the standard errors (0: analytic ones only).  The largest of the Laplace,
#: cluster-robust and bootstrap errors is reported, so ten refits guard against optimistic
#: analytic ones at half the cost of twenty: what lets a vector loop's calibration, with its slow
#: part and refined knots, fit in the noon step's five minutes.
BOOTSTRAP = 10
#: Significant digits of a calibrated value in the written file.
DIGITS = 5


def vehicle_priors(vehicle: Vehicle, names: Sequence[str] = FITTED) -> list[Prior]:
    """One prior per field: centred on the file's value, :data:`PRIOR_SHARE` of it wide.

    Bounds keep the file loadable and the model physical: positive time constants and
    rates, power terms >= 0 (and up to :data:`POWER_HIGH_W`: a thruster vehicle's pack may
    draw ten times a torpedo's), time constants down to a twentieth of the file's (a thruster
    vehicle answers far faster than a torpedo), ``max_speed`` free to fall below ``cruise_speed``
    (a vehicle slower than the autonomy's cruise command saturates at its own top speed),
    ``power_exponent`` within :data:`EXPONENT_RANGE`; the ascent rate's is
    :func:`planner.review.calibration_legs.ascent_prior`.
    """
    out = []
    for n in names:
        if n == "ascent_rate_mps":
            out.append(ascent_prior(vehicle.ascent_rate_mps))
            continue
        if n in SURFACE_TERMS:
            out.append(surface_prior(vehicle, n))
            continue
        if n not in FITTED:  # a calibration run's knot or water term
            out.append(term_prior(vehicle, n))
            continue
        c = float(getattr(vehicle, n))
        sd = max(PRIOR_SHARE * abs(c), PRIOR_SD_FLOOR[n])
        if n == "max_speed":
            low, high = c / 5.0, max(4.0 * c, c + 4 * sd)
        elif n in TIME_CONSTANTS:
            low, high = c / 20.0, max(5.0 * c, c + 5 * sd)
        elif n == "power_exponent":
            low, high = EXPONENT_RANGE
        elif n == "slow_share":
            low, high = 0.0, SLOW_SHARE_HIGH
        elif n == "slow_time_constant_s":
            low, high = c / 20.0, 10.0 * c
        elif n in ("hotel_w", "drag_w"):  # a real pack may draw kilowatts where the file says watts
            low, high = 0.0, max(POWER_HIGH_W, 50.0 * c)
        else:
            low, high = min(c / 5.0, c), max(5.0 * c, c + 5 * sd)
            low = max(low, 1e-3)
        out.append(Prior(n, c, sd, min(low, c), high))
    return out


@dataclass
class Calibration:
    """A fitted vehicle block and the fit behind it (see :func:`fit_vehicle`)."""

    vehicle: Vehicle  # the file's vehicle with the identified fields replaced
    original: Vehicle
    estimate: MapEstimate
    rms_before: dict[str, float]  # position_m, heading_deg, energy_wh under the file's vehicle
    rms_after: dict[str, float]  # the same under the calibrated vehicle
    segments: int
    runs: int
    logs: list[dict] = field(default_factory=list)  # name, sha256, scenario, steps (calibrate only)
    model_share: float = 0.0  # share of each value added to its s.e. for the replay's approximation
    water: DayWater | None = None  # the day's water written beside the vehicle (calibrate --bias)
    pack: PackReading | None = None  # the vehicle's own pack as its reports show it
    pack_limits_battery: bool = False  # battery_wh set to the pack's energy to the watchdog's limit
    ascent: AscentFit | None = None  # the ascent rate's own fit (also merged into ``estimate``)
    cut: list[CutLeg] = field(default_factory=list)  # calibration legs the back-seat did not finish
    run_water: Bias = field(default_factory=Bias)  # the current the calibration run flew in, relative to the mission's
    control: dict = field(default_factory=dict)  # the speed loop chosen: chosen, file, position_rms_m per loop

    def file_value(self, name: str) -> float:
        """A fitted term's value before the fit (the file's vehicle, the mission's water)."""
        return term_value(self.original, Bias(), name)

    def value(self, name: str) -> float:
        """A fitted term's calibrated value (a field, a knot's reached speed, the run's water)."""
        return term_value(self.vehicle, self.run_water, name)

    def unit(self, name: str) -> str:
        """A fitted term's unit."""
        return UNITS.get(name) or term_unit(name)

    @property
    def curve_fitted(self) -> bool:
        """Whether the speed curve replaced ``speed_gain`` and ``max_speed`` in this fit."""
        return any(knot_command(n) is not None for n in self.fitted)

    @property
    def water_identified(self) -> list[str]:
        """The water terms the run identified (``water.current_scale`` or ``water.current_offset``, ``water.current_cross``)."""
        return [n for n in self.fitted if is_water(n) and self.estimate.identified[n]]

    @property
    def fitted(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.estimate.priors)

    @property
    def unidentified(self) -> dict[str, str]:
        """Per parameter left at the file's value: the leg that would identify it (and any cut short)."""
        out = {}
        for n in self.fitted:
            if self.estimate.identified[n]:
                continue
            need = NEEDS[n] if n in NEEDS else term_need(n)[0]
            if n == "ascent_rate_mps" and self.ascent is not None and self.ascent.note:
                need = f"{need}; {self.ascent.note}"
            cut = self.cut_short(n)
            if cut:
                need += "; cut short: " + ", ".join(c.describe() for c in cut)
            out[n] = need
        return out

    def cut_short(self, name: str) -> list[CutLeg]:
        """The cut-short legs of a kind that identifies ``name``."""
        kinds = LEG_KINDS[name] if name in LEG_KINDS else term_need(name)[1]
        return [c for c in self.cut if c.kind in kinds]

    @property
    def unidentified_by_cut(self) -> list[str]:
        """Parameters left unidentified where a leg that would identify them was cut short."""
        return [n for n in self.fitted if not self.estimate.identified[n] and self.cut_short(n)]

    @property
    def stderr(self) -> dict[str, float]:
        """Per fitted field: the fit's standard error, with :attr:`model_share` of the value added in quadrature."""
        est = self.estimate
        return {
            n: float(np.hypot(est.stderr[n], self.model_share * abs(self.value(n))))
            if est.identified[n]
            else float(est.stderr[n])
            for n in self.fitted
        }

    def to_dict(self) -> dict:
        """What the JSON sidecar holds (no paths beyond the logs' names, no times: deterministic)."""
        est, se = self.estimate, self.stderr
        params = {}
        for p in est.priors:
            n = p.name
            params[n] = {
                "file_value": self.file_value(n),
                "calibrated": self.value(n),
                "stderr": se[n],
                "stderr_fit": float(est.stderr[n]),
                "identified": bool(est.identified[n]),
                "map_estimate": float(est.map_value[n]),
                "stderr_source": est.stderr_sources.get(n, ""),
                "unit": self.unit(n),
                "prior": {"centre": p.centre, "sd": p.sd, "low": p.low, "high": p.high},
            }
        return {
            "schema": CALIBRATION_SCHEMA,
            "parameters": params,
            "not_fitted": [
                f.name
                for f in dataclasses.fields(Vehicle)
                if f.name not in self.fitted
                and not (self.curve_fitted and f.name in ("speed_curve", "speed_gain", "max_speed"))
            ],
            "speed_curve": [list(k) for k in self.vehicle.speed_curve],
            "velocity_control": {"value": self.vehicle.velocity_control, **self.control},
            "unidentified": self.unidentified,
            "cut_short_legs": [dataclasses.asdict(c) for c in self.cut],
            "ascents_timed": 0 if self.ascent is None else self.ascent.events,
            "residual_rms": {"before": self.rms_before, "after": self.rms_after},
            "residual_sigmas": {
                "position_m": SIGMA_POSITION_M,
                "heading_deg": SIGMA_HEADING_DEG,
                "energy_wh": SIGMA_ENERGY_WH,
            },
            "correlation": est.correlation,
            "model_share": self.model_share,
            "segments": self.segments,
            "runs": self.runs,
            "bootstrap": est.bootstrap,
            "fit_converged": est.success,
            "logs": self.logs,
            **({"execution_bias": water_record(self.water)} if self.water is not None else {}),
            **({"pack": {**self.pack.to_dict(), "limits_battery_wh": self.pack_limits_battery}} if self.pack else {}),
        }


def fit_vehicle(
    mission: Mission,
    runs: list,
    start_times: Sequence[float],
    fit: Sequence[str] = FITTED,
    *,
    bootstrap: int = BOOTSTRAP,
    seed: int = 0,
    length: int = SEGMENT_STEPS,
    compared: Mapping[str, Any] | None = None,
) -> Calibration:
    """MAP fit of the ``[vehicle]`` fields ``fit`` to ``runs`` (:class:`planner.review.logs.LoggedRun`-like)
    flown from scenario start times ``start_times``; priors centred on ``mission.vehicle``.

    A calibration run's log adds its water (:func:`planner.review.calibration_terms.water_terms`) and
    speed curve and power (:func:`_legs_measured`).  Every term is *identified* when its posterior s.d. is below half its prior's
    (:data:`rapt.mapfit.IDENTIFIED_BELOW`, without :func:`rapt.mapfit.fit_map`'s survivor
    rule); the ascent rate is timed on its own (:func:`planner.review.calibration_legs.fit_ascent`).
    ``compared`` is the vehicle an earlier calibration of this vehicle found (``calibrate --bias``: the
    one the comparison predicted with): its speed loop is kept, not chosen again, and its turn is where
    the turn's fit starts.
    """
    unknown = [n for n in fit if n not in FITTED]
    if unknown or not fit:
        raise InputError(
            f"fit: unknown vehicle field {unknown[0] if unknown else fit!r}; choose from {', '.join(FITTED)}"
        )
    seg = segment_batch(mission, runs, list(start_times), length)
    if not seg.valid.any():
        raise InputError("LOGS: no replayable flight in the logs (no telemetry steps with set-points); nothing to fit")
    base = mission.vehicle
    cal = [(r, t) for r, t in zip(runs, start_times) if is_calibration_log(r)]
    cal_runs, cal_starts = [r for r, _ in cal], [t for _, t in cal]
    names = tuple(n for n in SEGMENT_FITTED if n in fit)
    slow = tuple(n for n in names if n in SLOW_TERMS)  # fitted only if the logs choose a vector loop
    names = tuple(n for n in names if n not in SLOW_TERMS)
    if cal_runs:  # the current the calibration run flew in, fitted beside the vehicle
        names = (*names, *water_terms(mission, cal_runs, cal_starts))
    loop, turn = _compared(compared)
    solver = SegmentSolver(mission, seg, vehicle_priors, bootstrap_blocks(seg)[np.nonzero(seg.valid)[0]], seed, turn)
    solve = solver.solve

    knots, power, first = _legs_measured(mission, cal_runs, cal_starts, names, solver)
    legs = {p.name: (p, v, map_value, se) for p, v, map_value, se in power}
    hotel = legs.pop("hotel_w", None)
    if knots:  # the rest fitted again with the measured curve in place of speed_gain and max_speed
        curve = tuple((float(knot_command(k.prior.name) or 0.0), k.value) for k in knots)
        base = dataclasses.replace(base, speed_curve=curve)
        if hotel:
            base = dataclasses.replace(base, hotel_w=hotel[1])
        names = tuple(n for n in names if n not in ("speed_gain", "max_speed") and not (hotel and n == "hotel_w"))
    # the surface terms a first time, above the legs' power curve, so the segments replay the surface
    # as the vehicle flew it (measured again over the fitted vehicle below)
    powered, _ = with_terms(base, {n: t[1] for n, t in legs.items()})
    base, _ = with_terms(base, surface_values(mission, runs, start_times, fit, powered, Bias()))
    # the hold leg measures the hotel load; the power curve above it is fitted to the segments (they see
    # the whole run, turns and accelerations included), searched from the legs' measurement, and where
    # the segments cannot pin it the legs' measurement stands
    start = {**first, **{n: t[1] for n, t in legs.items()}}  # both loops search from the first fit
    # a vector loop's slow part and the water trade against a settled speed measured on a leg's end:
    # under that loop the knots are refined on the segments with the rest, from their measurement
    vector_extra = slow + (tuple(knot_name(c) for c, _ in base.speed_curve) if knots else ())
    base, names, control, start = choose_loop(mission, seg, names, vector_extra, base, solve, start, loop)
    est = solve(names, base, bootstrap, start)
    # a knot the segments refine but cannot pin keeps its settled legs' measurement
    est = without_terms(
        est, [k.prior.name for k in knots if k.identified and not est.identified.get(k.prior.name, True)]
    )
    if legs and not all(est.identified[n] for n in legs):
        est = without_terms(est, list(legs))
    elif hotel:  # fitted over the pinned hotel load: its share of error is theirs too
        pinned = {n: float(np.hypot(est.stderr[n], LEG_POWER_SHARE * abs(est.value[n]))) for n in legs}
        est = dataclasses.replace(est, stderr={**est.stderr, **pinned})
        legs = {}
    else:
        legs = {}
    for p, v, map_value, se in ([hotel] if hotel else []) + list(legs.values()):
        est = with_independent(est, p, v, map_value, se, True, "settled legs")
    for k in (k for k in knots if k.prior.name not in est.names):
        source = "settled legs" if k.identified else "not identified"
        est = with_independent(est, k.prior, k.value, k.map_value, k.stderr, k.identified, source)
    est = with_surface(mission, runs, start_times, fit, base, est)
    est = monotone_curve(est)  # a file refuses a curve that falls; a saturated loop may read so
    ascent = fit_ascent(mission, runs, base.ascent_rate_mps) if "ascent_rate_mps" in fit else None
    if ascent is not None:
        est = with_ascent(est, ascent)
    calibrated, water = with_terms(base, {n: float(est.value[n]) for n in est.names})
    paced = seg.substeps is not None and bool(np.any(seg.substeps > 1))
    return Calibration(
        calibrated,
        mission.vehicle,
        est,
        rms_of(residual_parts(mission, seg, mission.vehicle)),
        rms_of(residual_parts(mission, seg, calibrated, water)),
        int(seg.valid.shape[0]),
        int(len(set(seg.run.tolist()))),
        model_share=MODEL_SHARE_PACED if paced else 0.0,
        ascent=ascent,
        run_water=water,
        control=control,
    )


def _compared(compared: Mapping[str, Any] | None) -> tuple[str | None, dict[str, float]]:
    """The speed loop and turn terms of an earlier calibration's vehicle (``fit_vehicle``'s ``compared``)."""
    c = compared or {}
    loop = c.get("velocity_control")
    turn = {n: float(c[n]) for n in TURN_TERMS if isinstance(c.get(n), (int, float))}
    return (loop if loop in ("surge", "vector") else None), turn


def _legs_measured(
    mission: Mission, cal_runs: list, cal_starts: Sequence[float], names: tuple[str, ...], solver: SegmentSolver
) -> tuple[list, list[tuple[Prior, float, float, float]], dict[str, float]]:
    """The calibration runs' (``cal_runs``, flown from ``cal_starts``) measured speed curve (the knots of
    :func:`planner.review.calibration_terms.fit_curve`; one a cut-short leg left unidentified keeps
    the file model's speed) and power terms
    (:func:`~planner.review.calibration_terms.fit_power`), both in the water a first fit finds;
    and where the first fit ended (its MAP values: a start for the fits that follow);
    ([], an empty fit) when its straight legs do not span
    :data:`~planner.review.calibration_terms.CURVE_MIN_SPEEDS` settled commanded speeds or the fit
    has no ``speed_gain`` and ``max_speed`` to replace.  The power terms come as (prior, value,
    MAP value, standard error) of those identified, :data:`LEG_POWER_SHARE` of each value added to
    its standard error."""
    if not cal_runs or not {"speed_gain", "max_speed"} <= set(names):
        return [], [], {}
    # the water is in the track: a first fit of the terms that move it, to positions and headings alone
    track = tuple(n for n in names if n not in POWER_TERMS)
    first = solver.solve_kinds(track, mission.vehicle, 0, None, ("position", "heading"))
    found = {n: float(first.map_value[n]) for n in first.names}
    # the knots are measured in the water the track fits best (its MAP), identified or not: a water left at its
    # prior would be the file's tide, which a vehicle that felt none would read as a slower speed through it
    water = with_terms(mission.vehicle, {n: float(first.map_value[n]) for n in first.names})[1]
    knots = fit_curve(mission, cal_runs, cal_starts, water)
    if sum(k.identified for k in knots) < CURVE_MIN_SPEEDS:
        return [], [], found
    terms = [n for n in POWER_TERMS if n in names]
    if len(terms) < len(POWER_TERMS):
        return knots, [], found
    power = fit_power(mission, cal_runs, cal_starts, water, vehicle_priors(mission.vehicle, terms))
    out = []
    for p in power.priors:
        v = power.value[p.name]
        se = float(np.hypot(power.stderr[p.name], LEG_POWER_SHARE * abs(v)))
        if power.identified[p.name] and se < IDENTIFIED_BELOW * p.sd:
            out.append((p, v, power.map_value[p.name], se))
    speed, used = leg_power_points(mission, cal_runs, cal_starts, water)
    if len(out) < len(power.priors) and power_curve_fits(power, speed, used, mission.vehicle.cruise_speed):
        # the terms together: one alone beside the file's others would be a curve no leg flew
        out = []
        for p in power.priors:
            v = power.map_value[p.name]
            out.append((p, v, v, float(np.hypot(power.stderr[p.name], LEG_POWER_SHARE * abs(v)))))
    return knots, out, found
