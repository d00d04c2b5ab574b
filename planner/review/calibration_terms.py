"""The terms a calibration run adds to the vehicle fit: a measured speed curve and the water it flew in.

A calibration run (``rapt-plan shakedown``) flies straight legs at several commanded speeds
on headings that come back on themselves.  Two things follow that plan runs at one cruise
speed cannot give:

- **The speed curve.**  A vehicle's velocity controller is seldom one gain of the command
  with one time constant: ArduSub's jumps to two thirds of a new speed in a few seconds,
  then creeps for a minute to what was asked (1 m/s for 1, 1.96 for 2), and saturates near
  2 m/s beyond.  A first-order model fitted to the whole leg splits the difference (a gain
  of 0.86), and a plan made with it has the vehicle 12 % slow for its whole mission.  So
  with straight legs at :data:`CURVE_MIN_SPEEDS` or more commanded speeds the speed it
  settles at is measured on each leg's settled part (:func:`fit_curve`: the through-water
  speed along the heading over the leg's last :data:`SETTLED_SHARE`, in the fitted water):
  ``speed_curve[2]`` is the m/s reached when 2 m/s is commanded, written as the file's
  ``[vehicle] speed_curve``, which then replaces ``speed_gain`` and ``max_speed`` in the
  vehicle's dynamics.
- **The water.**  Fitting a vehicle in water it was not in turns a current into a speed
  gain: the firmware feels no tide where the tide table says 0.2 m/s, and a fit in the
  table's water calls the vehicle 10 % slower than it is.  The run's out-and-back legs tell
  the current from the vehicle, so the current is fitted beside it: as ``current_scale``
  (the true tide over the table's) when the table's current during the run is at least
  :data:`TIDE_FOR_SCALE_MPS`, else as ``current_offset`` (m/s along the flood direction),
  the one a current the table says is slack can show; and always with ``current_cross``
  (m/s across the flood direction), which no scale of the table can give: with the two, a
  steady current from any direction (ArduSub SITL's, which knows no tide table).  ``rapt-plan calibrate`` writes it
  into the calibrated file's ``[execution_bias]``.

- **The vehicle at the surface.**  A thruster vehicle told to surface pushes itself against
  the surface and moves on with what its horizontal thrusters have left: ArduSub's BlueROV2
  model makes 0.33 m/s there whatever is asked, at 350 W.  A plan that has it transmit at
  the surface, or come home surfaced, is wrong by minutes without that.  Every stretch a
  log spends surfaced under a surface command, after :data:`SURFACE_SETTLE_S`, measures
  ``surface_max_speed`` (when commands there asked clearly more than it made) and
  ``surface_power_w`` (the draw above the speed's propulsion power): :func:`fit_surface`.

Term names are ``speed_curve[<commanded m/s>]`` and ``water.<bias field>``; the fit's other
names are ``[vehicle]`` fields.  :func:`term_value` and :func:`with_terms` read and set any
of them on a vehicle and a bias.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from planner.review.calibration_legs import legs_of, with_independent
from rapt.mapfit import IDENTIFIED_BELOW, MapEstimate, Prior, fit_map
from sim.uuv.bias import Bias, compose
from sim.uuv.environment import biased_tide
from sim.uuv.interface import HJ_PER_WH
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.vehicle import propulsion_power, reached_speed

__all__ = [
    "monotone_curve",
    "CURVE_MIN_SPEEDS",
    "TIDE_FOR_SCALE_MPS",
    "knot_name",
    "knot_command",
    "water_name",
    "is_water",
    "water_field",
    "water_terms",
    "term_value",
    "with_terms",
    "term_prior",
    "term_unit",
    "term_need",
    "KnotFit",
    "fit_curve",
    "fit_power",
    "leg_power_points",
    "power_curve",
    "power_curve_fits",
    "fit_surface",
    "surface_prior",
    "surface_values",
    "with_surface",
    "POWER_TERMS",
    "SURFACE_TERMS",
]

#: Fewest distinct commanded speeds of straight legs that make a curve worth fitting.
CURVE_MIN_SPEEDS = 3
#: The tide table's mean current (m/s) during the calibration legs above which the water is
#: fitted as a scale of the table; below it the table's tide is too weak to scale.
TIDE_FOR_SCALE_MPS = 0.1
#: Prior s.d. of a knot's reached speed as a share of the file model's (the vehicle fit's 30 %),
#: and its floor in m/s.
KNOT_SHARE, KNOT_SD_FLOOR = 0.3, 0.1
#: Priors of the water terms: (centre, s.d., low, high).  A tide table off by half its
#: amplitude, or a quarter-knot current it does not list, is what a range expects.
WATER_PRIORS = {
    "current_scale": (1.0, 0.5, 0.0, 3.0),
    "current_offset": (0.0, 0.3, -2.0, 2.0),
    "current_cross": (0.0, 0.3, -2.0, 2.0),
}
#: The share of a straight leg, at its end, over which its speed counts as settled.
SETTLED_SHARE = 0.5
#: Consecutive steps per block of the settled speeds' standard error (neighbouring steps share
#: the controller's slow wander, so they are not independent draws).
SE_BLOCK = 3
#: The power terms measured on the legs when a curve is: ``hotel_w + drag_w (v / cruise)^power_exponent``.
POWER_TERMS = ("hotel_w", "drag_w", "power_exponent")
#: Nominal error of a leg's settled power (W); the fit estimates the actual scale.
SIGMA_POWER_W = 10.0
#: How close the MAP power curve must come to every leg's power for the curve to count as identified whole.
CURVE_POWER_FIT = 0.05
#: A leg slower than this (m/s, through the water) is a hold.
HOLD_SPEED = 0.1
#: Smallest standard error of a settled speed (m/s): what a position fix's noise and the
#: model's own approximation leave however steady the leg.
SE_FLOOR_MPS = 0.01
#: The ``[vehicle]`` fields measured at the surface (:func:`fit_surface`).
SURFACE_TERMS = ("surface_max_speed", "surface_power_w")
#: Seconds at the surface before its speed and power count (the vehicle slows from its dived speed).
SURFACE_SETTLE_S = 10.0
#: A surface step counts as held back by the surface when the vehicle would reach this much more
#: submerged at its command than it made at the surface.
SURFACE_HELD_SHARE = 1.2
#: Prior s.d. floors of the surface terms (m/s, W).
SURFACE_SPEED_SD_FLOOR, SURFACE_POWER_SD_FLOOR = 0.1, 20.0
#: Commanded speeds (m/s) this close are one knot.
SAME_COMMAND = 0.05
_KNOT = re.compile(r"^speed_curve\[([0-9.eE+-]+)\]$")
_WATER = "water."


def knot_name(command: float) -> str:
    return f"speed_curve[{command:g}]"


def knot_command(name: str) -> float | None:
    """The commanded speed of a knot's name, None for any other name."""
    m = _KNOT.match(name)
    return float(m.group(1)) if m else None


def water_name(field: str) -> str:
    return _WATER + field


def is_water(name: str) -> bool:
    return name.startswith(_WATER)


def water_field(name: str) -> str:
    """The bias field of a water term (``water.current_scale`` -> ``current_scale``)."""
    return name[len(_WATER) :]


def water_terms(mission: Mission, runs: Sequence, start_times: Sequence[float]) -> tuple[str, str]:
    """``water.current_scale`` when the table's current over the calibration legs averages
    :data:`TIDE_FOR_SCALE_MPS` or more, else ``water.current_offset``; and ``water.current_cross``."""
    speeds = []
    b = mission.execution_bias
    for run, t0 in zip(runs, start_times):
        legs = legs_of(run)
        if not legs:
            continue
        t = np.linspace(min(leg["t0_s"] for leg in legs), max(leg["t1_s"] for leg in legs), 50)
        ce, cn = biased_tide(mission.current, t0 + b.start_time + t, b)
        speeds.append(np.hypot(ce, cn))
    strong = bool(speeds) and float(np.mean(np.concatenate(speeds))) >= TIDE_FOR_SCALE_MPS
    return water_name("current_scale" if strong else "current_offset"), water_name("current_cross")


def term_value(vehicle: Vehicle, water: Bias, name: str) -> float:
    """A term's value: a ``[vehicle]`` field, the reached speed at a knot's command, or a water field."""
    cmd = knot_command(name)
    if cmd is not None:
        return float(reached_speed(vehicle, cmd))
    if is_water(name):  # to a micro-unit: a fit pressed against its bound reads 0, not 1e-16
        return round(float(getattr(water, water_field(name))), 6)
    return float(getattr(vehicle, name))


def with_terms(vehicle: Vehicle, values: Mapping[str, float]) -> tuple[Vehicle, Bias]:
    """``vehicle`` with ``values``' fields and knots set, and the (relative) water bias of its water terms.

    Knots given replace the vehicle's whole speed curve: they are the curve.
    """
    fields: dict[str, float] = {}
    knots: list[tuple[float, float]] = []
    water: dict[str, float] = {}
    for n, v in values.items():
        cmd = knot_command(n)
        if cmd is not None:
            knots.append((cmd, max(float(v), 0.0)))
        elif is_water(n):
            water[water_field(n)] = float(v)
        else:
            fields[n] = float(v)
    out = dataclasses.replace(vehicle, **fields)  # type: ignore[arg-type]  # float fields only
    if knots:
        out = dataclasses.replace(out, speed_curve=tuple(sorted(knots)))
    return out, Bias(**water)


def term_prior(vehicle: Vehicle, name: str) -> Prior:
    """The prior of a knot (centred on the file model's reached speed) or a water term."""
    cmd = knot_command(name)
    if cmd is not None:
        c = float(reached_speed(vehicle, cmd))
        sd = max(KNOT_SHARE * c, KNOT_SD_FLOOR)
        return Prior(name, c, sd, 0.0, max(4.0 * c, c + 5 * sd, 1.5 * cmd))
    centre, sd, low, high = WATER_PRIORS[water_field(name)]
    return Prior(name, centre, sd, low, high)


def term_unit(name: str) -> str:
    if knot_command(name) is not None:
        return "m/s"
    return "x" if name.endswith("scale") else "m/s"


def term_need(name: str) -> tuple[str, tuple[str, ...]]:
    """The leg that identifies a knot or water term, and the leg kinds that are it."""
    cmd = knot_command(name)
    if cmd is not None:
        return f"a straight leg commanded at {cmd:g} m/s, long enough to settle", ("straight",)
    return "straight legs on opposite headings (out and back)", ("straight",)


@dataclass
class KnotFit:
    """The settled speed at one commanded speed, with its prior and posterior (as the ascent rate's)."""

    prior: Prior
    value: float  # identified: the posterior mean; otherwise the file model's reached speed
    map_value: float
    stderr: float
    identified: bool
    steps: int  # settled steps measured
    note: str  # why not identified ("" when it is)


def _settled(mission: Mission, run, t0: float, water: Bias, leg: dict) -> tuple[float, np.ndarray, float]:
    """A ``leg``'s mean commanded speed, its through-water speeds along the heading and its mean
    electrical power (W), over its settled, flown, submerged steps (NaN and none when too few)."""
    s, sp = run.steps, run.setpoints
    t = s[:, 0]
    start = leg["t1_s"] - SETTLED_SHARE * (leg["t1_s"] - leg["t0_s"])
    keep = (t >= start) & (t <= leg["t1_s"]) & np.isfinite(sp[:, 1]) & (np.nan_to_num(sp[:, 2], nan=0.0) < 0.5)
    if t.size < 3 or keep.sum() < 2:
        return math.nan, np.zeros(0), math.nan
    b = compose(mission.execution_bias, water)
    ve, vn = np.gradient(s[:, 1], t), np.gradient(s[:, 2], t)
    ce, cn = biased_tide(mission.current, t0 + b.start_time + t, b)
    course = s[:, 3] + np.deg2rad(b.heading)
    surge = (ve - ce) * np.sin(course) + (vn - cn) * np.cos(course)
    first, last = np.flatnonzero(keep)[[0, -1]]
    power = (s[last, 4] - s[first, 4]) / HJ_PER_WH * 3600.0 / (t[last] - t[first])
    return float(np.mean(sp[keep, 1])), surge[keep], float(power)


def _measured(prior: Prior, v: np.ndarray, floor: float, too_few: str, wanders: str) -> KnotFit:
    """The mean of per-step measurements ``v`` combined with ``prior`` (as the ascent rate's): a
    standard error from means of :data:`SE_BLOCK`-step blocks, at least ``floor``; identified when
    the posterior s.d. is below :data:`rapt.mapfit.IDENTIFIED_BELOW` of the prior's.  ``too_few``
    and ``wanders`` are the notes when it is not."""
    blocks = v.size // SE_BLOCK
    if blocks < 2:
        return KnotFit(prior, prior.centre, prior.centre, prior.sd, False, int(v.size), too_few)
    means = v[: blocks * SE_BLOCK].reshape(blocks, SE_BLOCK).mean(axis=1)
    se = max(float(means.std(ddof=1)) / math.sqrt(blocks), floor)
    w_data, w_prior = 1 / se**2, 1 / prior.sd**2
    post = min(max((float(v.mean()) * w_data + prior.centre * w_prior) / (w_data + w_prior), prior.low), prior.high)
    post_sd = 1 / math.sqrt(w_data + w_prior)
    ident = post_sd < IDENTIFIED_BELOW * prior.sd
    return KnotFit(prior, post if ident else prior.centre, post, post_sd, ident, int(v.size), "" if ident else wanders)


def _knot(prior: Prior, cmd: float, v: np.ndarray) -> KnotFit:
    """The settled speeds ``v`` at ``cmd`` combined with the knot's prior."""
    return _measured(
        prior,
        v,
        SE_FLOOR_MPS,
        f"{v.size} settled step(s) at {cmd:g} m/s: too few to measure the speed",
        f"the speed at {cmd:g} m/s wanders too much over its leg to settle",
    )


def fit_curve(mission: Mission, runs: Sequence, start_times: Sequence[float], water: Bias) -> list[KnotFit]:
    """One :class:`KnotFit` per commanded speed of the calibration runs' straight legs, ascending.

    Each leg's command is the mean set-point over its settled part (a leg crabbing against
    the tide table commands a little more or less than its nominal speed); legs within
    :data:`SAME_COMMAND` m/s of each other are pooled.  The settled speeds' mean, with a
    standard error from means of :data:`SE_BLOCK`-step blocks, is combined with the knot's
    prior (:func:`term_prior`); identified when the posterior s.d. is below
    :data:`rapt.mapfit.IDENTIFIED_BELOW` of the prior's.
    """
    pooled: list[tuple[float, list[np.ndarray]]] = []
    for run, t0 in zip(runs, start_times):
        for leg in legs_of(run):
            if leg["kind"] != "straight":
                continue
            cmd, v, _ = _settled(mission, run, t0, water, leg)
            if not math.isfinite(cmd):  # cut short before it settled: a knot still to measure
                cmd = float(leg.get("speed", math.nan))
            if not math.isfinite(cmd) or cmd <= 0:
                continue
            near = next((g for g in pooled if abs(g[0] - cmd) <= SAME_COMMAND), None)
            if near is None:
                pooled.append((cmd, [v]))
            else:
                near[1].append(v)
    out = []
    for cmd, vs in sorted(pooled, key=lambda g: g[0]):
        cmd = round(cmd, 3)
        out.append(_knot(term_prior(mission.vehicle, knot_name(cmd)), cmd, np.concatenate(vs)))
    return out


def leg_power_points(
    mission: Mission, runs: Sequence, start_times: Sequence[float], water: Bias
) -> tuple[np.ndarray, np.ndarray]:
    """Each straight and hold leg's settled (through-water speed, power): its energy used over its settled
    part, and its mean speed there."""
    points = []
    for run, t0 in zip(runs, start_times):
        for leg in legs_of(run):
            if leg["kind"] in ("straight", "hold"):
                _, v, watts = _settled(mission, run, t0, water, leg)
                if v.size >= 2 and math.isfinite(watts):
                    points.append((abs(float(v.mean())), watts))
    return np.array([v for v, _ in points], dtype=float), np.array([w for _, w in points], dtype=float)


def power_curve(theta: Sequence[float] | np.ndarray, speed: np.ndarray, cruise: float) -> np.ndarray:
    """``hotel_w + drag_w (v / cruise)^power_exponent`` at ``speed``; ``theta`` in :data:`POWER_TERMS` order."""
    hotel, drag, k = theta
    return hotel + drag * (np.asarray(speed, dtype=float) / cruise) ** k


def fit_power(
    mission: Mission, runs: Sequence, start_times: Sequence[float], water: Bias, priors: Sequence[Prior]
) -> MapEstimate:
    """The power terms (:data:`POWER_TERMS`, ``priors`` in that order) fitted to each straight and
    hold leg's settled (speed, power) (:func:`leg_power_points`): the hold gives the hotel load, the
    speeds the curve above it. The MAP fit and its identification are :func:`rapt.mapfit.fit_map`'s,
    a leg one residual.
    """
    speed, used = leg_power_points(mission, runs, start_times, water)
    cruise = mission.vehicle.cruise_speed

    def residuals(theta: np.ndarray) -> np.ndarray:
        return (power_curve(theta, speed, cruise) - used) / SIGMA_POWER_W

    return fit_map(residuals, priors, significant=0.0)


def power_curve_fits(fit: MapEstimate, speed: np.ndarray, used: np.ndarray, cruise: float) -> bool:
    """Whether the MAP power curve of ``fit`` reproduces every leg's power (within :data:`CURVE_POWER_FIT`
    of it, or :data:`SIGMA_POWER_W` x 3) from at least two distinct speeds and a hold, with no term pinned at
    a bound of its prior: the curve is then identified as a whole even where its terms, correlated (a
    thruster vehicle's legs at one saturated speed), are not one by one."""
    if speed.size < 3 or np.unique(np.round(speed[speed > HOLD_SPEED], 1)).size < 2 or not (speed <= HOLD_SPEED).any():
        return False
    theta = [fit.map_value[n] for n in POWER_TERMS]
    if any(not (p.low < fit.map_value[p.name] < p.high) for p in fit.priors):
        return False
    miss = np.abs(power_curve(theta, speed, cruise) - used)
    return bool(np.all(miss <= np.maximum(CURVE_POWER_FIT * used, 3 * SIGMA_POWER_W)))


def surface_prior(vehicle: Vehicle, name: str) -> Prior:
    """The prior of a surface term: the file's value, 30 % wide; a file without a surface limit
    gets one centred on its cruise speed's reached speed, and no extra draw one as wide as a
    third of its hotel and drag."""
    if name == "surface_max_speed":
        c = vehicle.surface_max_speed or float(reached_speed(vehicle, vehicle.cruise_speed))
        sd = max(KNOT_SHARE * c, SURFACE_SPEED_SD_FLOOR)
        return Prior(name, c, sd, 0.0, max(4.0 * c, c + 5 * sd))
    c = vehicle.surface_power_w
    sd = max(KNOT_SHARE * abs(c), KNOT_SHARE * (vehicle.hotel_w + vehicle.drag_w), SURFACE_POWER_SD_FLOOR)
    return Prior(name, c, sd, -vehicle.hotel_w, max(20000.0, c + 5 * sd))


def _surface_steps(mission: Mission, run, t0: float, water: Bias) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per settled surface step of ``run``: commanded speed, through-water speed and electrical power (W).

    A step counts when the vehicle reported itself surfaced under a surface command it was
    flying, had been so for :data:`SURFACE_SETTLE_S`, and the next report follows within the
    decision period's tolerance.
    """
    s, sp = run.steps, run.setpoints
    n = s.shape[0]
    if n < 3 or sp.shape[1] < 3:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    t = s[:, 0]
    up = (s[:, 5] > 0.5) & (np.nan_to_num(sp[:, 2], nan=0.0) > 0.5) & np.isfinite(sp[:, 1])
    since = np.full(n, -np.inf)  # when the current surfaced stretch began
    for i in range(n):
        since[i] = (since[i - 1] if i and up[i - 1] else t[i]) if up[i] else -np.inf
    ok = np.zeros(n, dtype=bool)
    ok[:-1] = up[:-1] & up[1:] & (t[:-1] - since[:-1] >= SURFACE_SETTLE_S)
    ok[:-1] &= np.abs(np.diff(t) - mission.dt) <= 0.5 * mission.dt
    b = compose(mission.execution_bias, water)
    ce, cn = biased_tide(mission.current, t0 + b.start_time + t, b)
    h = np.diff(t)
    k = np.flatnonzero(ok)
    speed = np.hypot(np.diff(s[:, 1])[k] / h[k] - ce[k], np.diff(s[:, 2])[k] / h[k] - cn[k])
    power = np.diff(s[:, 4])[k] / HJ_PER_WH * 3600.0 / h[k]
    return sp[k, 1], speed, power


def fit_surface(
    mission: Mission, runs: Sequence, start_times: Sequence[float], water: Bias, vehicle: Vehicle
) -> list[KnotFit]:
    """``surface_max_speed`` and ``surface_power_w`` from every log's settled surface steps
    (:func:`_surface_steps`), in the fitted ``water``, above ``vehicle``'s dived model; [] when the
    logs spend no settled time at the surface.

    The limit counts the steps whose command the vehicle would turn into at least
    :data:`SURFACE_HELD_SHARE` times the step's speed submerged: a vehicle that makes what
    it is asked at the surface shows no limit, and keeps the file's.  The extra draw is each
    step's power less the propulsion power of its speed.
    """
    cmds, speeds, powers = [], [], []
    for run, t0 in zip(runs, start_times):
        c, v, w = _surface_steps(mission, run, t0, water)
        cmds.append(c)
        speeds.append(v)
        powers.append(w)
    cmd, speed, power = (np.concatenate(a) if a else np.zeros(0) for a in (cmds, speeds, powers))
    if cmd.size == 0:
        return []
    held = reached_speed(vehicle, cmd) >= SURFACE_HELD_SHARE * speed
    cap = _measured(
        surface_prior(vehicle, "surface_max_speed"),
        speed[held],
        SE_FLOOR_MPS,
        f"{int(held.sum())} settled surface step(s) commanded faster than the vehicle went there: "
        "it made what it was asked at the surface",
        "the speed at the surface wanders too much to settle",
    )
    if not cap.identified:  # no limit seen: the file's (0, none) stands, not the prior's centre
        cap = dataclasses.replace(cap, value=vehicle.surface_max_speed)
    extra = power - propulsion_power(vehicle, speed)
    draw = _measured(
        surface_prior(vehicle, "surface_power_w"),
        extra,
        SIGMA_POWER_W / 10.0,
        f"{speed.size} settled surface step(s): too few to measure the draw there",
        "the draw at the surface wanders too much to settle",
    )
    return [cap, draw]


#: A surface term this many standard errors or less from the file's value confirms it.
SAME_AS_FILE_SE = 2.0


def surface_values(
    mission: Mission, runs: list, start_times: Sequence[float], fit: Sequence[str], vehicle: Vehicle, water: Bias
) -> dict[str, float]:
    """The surface terms of ``fit`` the logs identify above ``vehicle`` in ``water``: {field: value}."""
    if not any(n in fit for n in SURFACE_TERMS):
        return {}
    found = fit_surface(mission, runs, list(start_times), water, vehicle)
    return {f.prior.name: f.value for f in found if f.identified and f.prior.name in fit}


def with_surface(
    mission: Mission, runs: list, start_times: Sequence[float], fit: Sequence[str], base: Vehicle, est: MapEstimate
) -> MapEstimate:
    """``est`` with the surface terms asked for in ``fit``, measured on the logs' settled surface steps
    above the vehicle fitted so far (:func:`planner.review.calibration_terms.fit_surface`); unidentified
    at the file's values when the logs spend no settled time at the surface.  A term within
    :data:`SAME_AS_FILE_SE` standard errors of the file's value keeps it: a vehicle that shows no
    surface effect leaves a file without one as it was."""
    names = [n for n in SURFACE_TERMS if n in fit]
    if not names:
        return est
    vehicle, water = with_terms(base, {n: float(est.value[n]) for n in est.names})
    vehicle = dataclasses.replace(vehicle, **{n: getattr(mission.vehicle, n) for n in SURFACE_TERMS})
    found = {f.prior.name: f for f in fit_surface(mission, runs, list(start_times), water, vehicle)}
    for n in names:
        f = found.get(n)
        file_value = getattr(mission.vehicle, n)
        if f is None:
            p = surface_prior(mission.vehicle, n)
            est = with_independent(est, p, file_value, p.centre, p.sd, False, "not identified")
        else:
            source = "surface steps" if f.identified else "not identified"
            value = f.value if f.identified else file_value
            if f.identified and abs(value - file_value) <= SAME_AS_FILE_SE * f.stderr:
                value, source = file_value, "surface steps (the file's value, within the error)"
            est = with_independent(est, f.prior, value, f.map_value, f.stderr, f.identified, source)
    return est


def monotone_curve(est: MapEstimate) -> MapEstimate:
    """``est`` with its speed-curve knots made non-decreasing in the command.

    A vehicle never goes slower for being asked to go faster; a saturated speed loop measured leg by leg can read
    a little lower at a higher command (a leg flown after a turn, a gust of current), and a mission file refuses
    a curve that falls. Adjacent knots that fall are pooled to their mean weighted by 1/s.e.^2 (the
    pool-adjacent-violators fit of an increasing curve); each keeps its own s.e.
    """
    knots = sorted((c, n) for n in est.names if (c := knot_command(n)) is not None)
    blocks: list[list] = []  # [value, weight, names]
    for _, n in knots:
        se = est.stderr.get(n) or 0.0
        blocks.append([float(est.value[n]), 1.0 / se**2 if se > 0 else 1.0, [n]])
        while len(blocks) > 1 and blocks[-2][0] > blocks[-1][0]:
            v2, w2, n2 = blocks.pop()
            v1, w1, n1 = blocks.pop()
            blocks.append([(v1 * w1 + v2 * w2) / (w1 + w2), w1 + w2, n1 + n2])
    value = dict(est.value)
    for v, _, names in blocks:
        value.update(dict.fromkeys(names, v))
    return dataclasses.replace(est, value=value)
