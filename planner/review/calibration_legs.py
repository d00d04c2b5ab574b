"""What a calibration log's legs say: which leg identifies which parameter, which legs were cut short, the ascent rate.

A calibration run (``rapt-plan shakedown``) flies legs chosen to identify the vehicle, and
its log's scenario record (``meta/scenario``) lists them: ``legs`` is a list of
``{kind, name, start_s, end_s, speed, ...}`` in mission seconds (the log's step clock), with
the kinds of :data:`sim.uuv.legs.LEG_KINDS` (``straight``, ``turn``, ``hold``, ``ascent``,
``dive``, ``return``; the return leg's ``end_s`` is a limit, not a plan: it ends when the
vehicle is recovered).  Such a log is a
calibration on its own (:func:`is_calibration_log`).  A parameter the fit leaves
unidentified is named with the leg that would identify it (:data:`NEEDS`), and when a leg
of that kind was cut short (the back-seat stopped flying before its ``end_s``: the watchdog or
a pilot took over, or the log ended) :func:`cut_legs` says which and why.

The ascent rate is not seen in the positions and energy the segment replay fits, only in
the time from a surface command to the vehicle reporting itself surfaced: :func:`fit_ascent`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from rapt.mapfit import IDENTIFIED_BELOW, MapEstimate, Prior
from sim.uuv.interface import DEPTH_M
from sim.uuv.mission import Mission

__all__ = [
    "NEEDS",
    "LEG_KINDS",
    "AscentFit",
    "CutLeg",
    "legs_of",
    "is_calibration_log",
    "cut_legs",
    "fit_ascent",
    "ascent_prior",
    "empty_estimate",
    "with_ascent",
    "with_independent",
    "without_terms",
    "merged",
]

#: The leg that identifies each fitted parameter, as a test engineer would fly it.
NEEDS = {
    "speed_gain": "a speed leg below saturation",
    "max_speed": "a speed leg above saturation (a command faster than the vehicle goes)",
    "surge_time_constant_s": "a speed leg that starts from another speed",
    "max_turn_rate_dps": "a turn at the turn-rate limit",
    "yaw_time_constant_s": "a turn",
    "heading_time_s": "a turn (the heading error the autopilot closes)",
    "hotel_w": "a hold (speed 0)",
    "drag_w": "a speed leg",
    "power_exponent": "speed legs at 3 or more speeds",
    "slow_share": "a speed leg long enough for the speed loop's slow part to settle (a minute or more)",
    "slow_time_constant_s": "a speed leg long enough for the speed loop's slow part to settle (a minute or more)",
    "ascent_rate_mps": "an ascent (a surface command from depth)",
    "surface_max_speed": "an ascent leg that stays at the surface, commanded faster than the vehicle goes there",
    "surface_power_w": "an ascent leg that stays at the surface",
}
#: The leg kinds that identify each fitted parameter.
LEG_KINDS = {
    "speed_gain": ("straight",),
    "max_speed": ("straight",),
    "surge_time_constant_s": ("straight",),
    "max_turn_rate_dps": ("turn",),
    "yaw_time_constant_s": ("turn",),
    "heading_time_s": ("turn",),
    "hotel_w": ("hold",),
    "drag_w": ("straight",),
    "power_exponent": ("straight", "hold"),
    "slow_share": ("straight",),
    "slow_time_constant_s": ("straight",),
    "ascent_rate_mps": ("ascent",),
    "surface_max_speed": ("ascent",),
    "surface_power_w": ("ascent",),
}
#: Prior of the ascent rate when the file says 0 (instantaneous): a nominal rate, as wide as itself.
ASCENT_NOMINAL_MPS = 0.5
#: Smallest prior s.d. of the ascent rate (m/s).
ASCENT_SD_FLOOR = 0.1
#: Largest ascent rate the fit considers (m/s): faster than any vehicle surfaces.
ASCENT_HIGH_MPS = 10.0


@dataclass(frozen=True)
class CutLeg:
    """A leg of a log that the back-seat did not fly to its end."""

    log: str
    kind: str
    name: str
    t1_s: float
    flown_until_s: float
    reason: str

    def describe(self) -> str:
        return (
            f"{self.kind} leg {self.name!r} of {self.log} cut at {self.flown_until_s:.0f} s of {self.t1_s:.0f} s "
            f"({self.reason})"
        )


def legs_of(run) -> list[dict]:
    """The calibration legs in a run's scenario record (a list, or its JSON text), [] when it has none.

    Only legs with a kind and finite ``start_s`` < ``end_s`` count; they come back with ``t0_s`` and ``t1_s``.
    """
    raw = getattr(run, "meta", {}).get("legs")
    if isinstance(raw, str):
        try:
            raw = json.loads(raw)
        except ValueError:
            return []
    if not isinstance(raw, list):
        return []
    out = []
    for i, leg in enumerate(raw):
        if not isinstance(leg, dict) or not isinstance(leg.get("kind"), str):
            continue
        try:
            t0, t1 = float(leg.get("start_s", math.nan)), float(leg.get("end_s", math.nan))
        except (TypeError, ValueError):
            continue
        if math.isfinite(t0) and math.isfinite(t1) and t0 < t1:
            out.append({**leg, "name": str(leg.get("name", f"leg{i}")), "t0_s": t0, "t1_s": t1})
    return out


def is_calibration_log(run) -> bool:
    """A log whose scenario record lists calibration legs: enough for a calibration on its own."""
    return bool(legs_of(run))


def _flown_until(run) -> float:
    """The last step time at which the back-seat's set-point was still flown (-inf: none)."""
    sp, t = run.setpoints, run.steps[:, 0]
    flown = np.flatnonzero(np.isfinite(sp[:, 1])) if sp.size else np.zeros(0, dtype=np.int64)
    return float(t[flown[-1]]) if flown.size else -math.inf


def _why_cut(run) -> str:
    """Why the back-seat stopped flying, from the log's events and end."""
    for ev in getattr(run, "events", []) or []:
        if ev.get("source") == "watchdog" and ev.get("event") == "intervention":
            return f"the watchdog took over: {ev.get('reason', 'unknown reason')}"
    for ev in getattr(run, "events", []) or []:
        if str(ev.get("source", "")) in ("operator", "pilot") or "pilot" in str(ev.get("event", "")):
            return "a pilot took over"
    ended = str(getattr(run, "ended", "") or "")
    if ended:
        return ended
    if not getattr(run, "complete_file", True):
        return "the log is cut off (damaged or the logger stopped)"
    return "the log ended (a pilot or the watchdog took over, or the run was stopped)"


def cut_legs(runs: Sequence, names: Sequence[str], dt: float) -> list[CutLeg]:
    """Every leg of ``runs`` (named ``names``) that ends more than one step ``dt`` after its flight did."""
    out = []
    for run, name in zip(runs, names):
        until = _flown_until(run)
        for leg in legs_of(run):
            if leg["kind"] == "return":  # ends when the vehicle is recovered, not at its end_s
                continue
            if leg["t1_s"] > until + dt + 1e-6:
                out.append(CutLeg(name, leg["kind"], leg["name"], leg["t1_s"], max(until, 0.0), _why_cut(run)))
    return out


# -- the ascent rate ------------------------------------------------------------------------
@dataclass
class AscentFit:
    """The ascent rate from surface-command-to-surfaced delays, with its prior and posterior."""

    prior: Prior
    value: float  # identified: the posterior mean; otherwise the file's value
    map_value: float  # the posterior mean whatever its width (the file's value without data)
    stderr: float  # posterior s.d. (the prior's without data)
    identified: bool
    events: int  # ascents timed
    note: str  # why not identified, when it is not ("" when it is)


def ascent_prior(file_value: float) -> Prior:
    """Centred on the file's rate, :data:`PRIOR_SHARE`-like 30 % wide; a file value of 0 (instantaneous)
    gives a nominal :data:`ASCENT_NOMINAL_MPS` prior as wide as itself, so the logs decide."""
    c = float(file_value) if file_value > 0 else ASCENT_NOMINAL_MPS
    sd = max(0.3 * c if file_value > 0 else c, ASCENT_SD_FLOOR)
    return Prior("ascent_rate_mps", c, sd, 1e-3, max(ASCENT_HIGH_MPS, 2 * c))


def _ascent_delays(run) -> list[tuple[float, float]]:
    """(delay s, report period s) per ascent: a surface command given submerged, held until surfaced."""
    s, sp = run.steps, run.setpoints
    n = s.shape[0]
    if n < 2 or sp.shape[1] < 3:
        return []
    surf_cmd = np.nan_to_num(sp[:, 2], nan=0.0) > 0.5
    surfaced = s[:, 5] > 0.5
    out = []
    for k in range(n - 1):
        if not surf_cmd[k] or surfaced[k] or (k > 0 and surf_cmd[k - 1]):
            continue
        j = k + 1
        while j < n and not surfaced[j] and surf_cmd[j - 1]:
            j += 1
        if j < n and surfaced[j] and surf_cmd[j - 1]:
            period = float(np.median(np.diff(s[max(k - 1, 0) : j + 1, 0])))
            out.append((float(s[j, 0] - s[k, 0]), period))
    return out


def fit_ascent(mission: Mission, runs: Sequence, file_value: float) -> AscentFit:
    """The rise time from :data:`sim.uuv.interface.DEPTH_M` of each logged ascent, and the rate it gives.

    An ascent seen ``d`` s after its command, in reports ``p`` s apart, took between ``d - p``
    and ``d`` s: its estimate is ``d - p/2`` with the uniform's s.d. ``p/sqrt(12)``, a share
    every ascent may have in common (one report phase), so it is not divided by their number;
    the spread of the ascents adds its standard error.  The rate ``DEPTH_M / T`` (delta
    method) is combined with :func:`ascent_prior`; identified when the posterior s.d. is below
    :data:`rapt.mapfit.IDENTIFIED_BELOW` of the prior's.  Every ascent within one report: the
    vehicle surfaces faster than the logs resolve, and the rate stays the file's.
    """
    prior = ascent_prior(file_value)
    delays = [d for run in runs for d in _ascent_delays(run)]
    keep = AscentFit(prior, float(file_value), float(file_value), prior.sd, False, len(delays), "")
    if not delays:
        keep.note = "no ascent in the logs"
        return keep
    d = np.array([x for x, _ in delays])
    p = np.array([y for _, y in delays])
    rise = d - p / 2
    if np.all(d <= p + 1e-6):
        keep.note = f"surfaced within one report on all {len(delays)} ascent(s): faster than the logs resolve"
        return keep
    t_hat = float(np.mean(rise))
    se_t = math.sqrt(float(np.mean(p**2)) / 12 + (float(np.var(rise, ddof=1)) / d.size if d.size > 1 else 0.0))
    rate = DEPTH_M / t_hat
    se_rate = DEPTH_M / t_hat**2 * se_t
    w_data, w_prior = 1 / se_rate**2, 1 / prior.sd**2
    post = (rate * w_data + prior.centre * w_prior) / (w_data + w_prior)
    post_sd = 1 / math.sqrt(w_data + w_prior)
    post = min(max(post, prior.low), prior.high)
    ident = post_sd < IDENTIFIED_BELOW * prior.sd
    note = "" if ident else f"{len(delays)} ascent(s) too coarsely timed for the rate"
    return AscentFit(prior, post if ident else float(file_value), post, post_sd, ident, len(delays), note)


def empty_estimate() -> MapEstimate:
    """A fit of nothing (only the ascent rate asked for), for :func:`with_ascent` to extend."""
    return MapEstimate((), {}, {}, {}, {}, {}, 0, True, "nothing fitted to the segments")


def with_independent(
    est: MapEstimate, prior: Prior, value: float, map_value: float, stderr: float, identified: bool, source: str
) -> MapEstimate:
    """``est`` with one more parameter fitted on its own (its covariance block is its own)."""
    n = prior.name
    cov = est.covariance
    if identified:
        k = cov.shape[0]
        grown = np.zeros((k + 1, k + 1))
        grown[:k, :k] = cov
        grown[k, k] = stderr**2
        cov = grown
    return dataclasses.replace(
        est,
        priors=(*est.priors, prior),
        value={**est.value, n: value},
        map_value={**est.map_value, n: map_value},
        stderr={**est.stderr, n: stderr},
        identified={**est.identified, n: identified},
        covariance=cov,
        stderr_sources={**est.stderr_sources, n: source},
    )


def merged(a: MapEstimate, b: MapEstimate) -> MapEstimate:
    """Two fits of disjoint parameters as one (their covariance blocks apart: independent)."""
    ka, kb = a.covariance.shape[0], b.covariance.shape[0]
    cov = np.zeros((ka + kb, ka + kb))
    cov[:ka, :ka], cov[ka:, ka:] = a.covariance, b.covariance
    return dataclasses.replace(
        a,
        priors=(*a.priors, *b.priors),
        value={**a.value, **b.value},
        map_value={**a.map_value, **b.map_value},
        stderr={**a.stderr, **b.stderr},
        identified={**a.identified, **b.identified},
        noise_scale={**b.noise_scale, **a.noise_scale},
        residuals=a.residuals + b.residuals,
        success=a.success and b.success,
        message=a.message if a.message == b.message else f"{a.message}; {b.message}",
        correlation={**a.correlation, **b.correlation},
        covariance=cov,
        bootstrap=max(a.bootstrap, b.bootstrap),
        stderr_sources={**a.stderr_sources, **b.stderr_sources},
    )


def without_terms(est: MapEstimate, names: Sequence[str]) -> MapEstimate:
    """``est`` without the parameters ``names`` (and their rows of the covariance and correlations)."""
    drop = set(names)
    kept = [i for i, n in enumerate(est.identified_names) if n not in drop]
    cov = est.covariance[np.ix_(kept, kept)] if est.covariance.size else est.covariance
    return dataclasses.replace(
        est,
        priors=tuple(p for p in est.priors if p.name not in drop),
        value={n: v for n, v in est.value.items() if n not in drop},
        map_value={n: v for n, v in est.map_value.items() if n not in drop},
        stderr={n: v for n, v in est.stderr.items() if n not in drop},
        identified={n: v for n, v in est.identified.items() if n not in drop},
        covariance=cov,
        correlation={
            n: {m: c for m, c in row.items() if m not in drop} for n, row in est.correlation.items() if n not in drop
        },
        stderr_sources={n: v for n, v in est.stderr_sources.items() if n not in drop},
    )


def with_ascent(est: MapEstimate, a: AscentFit) -> MapEstimate:
    """``est`` with the ascent rate appended (:func:`with_independent`)."""
    source = "ascent timing" if a.identified else "not identified"
    return with_independent(est, a.prior, a.value, a.map_value, a.stderr, a.identified, source)
