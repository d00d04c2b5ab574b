"""Estimate the execution bias (:mod:`sim.uuv.bias`) from logged runs, jointly, with an uncertainty.

Why replay rather than re-fly.  Re-simulating each scenario closed loop under a trial
bias and matching its trajectory is what a range team does by eye, but as a function of
the bias it jumps: a waypoint reached one 2-s step earlier, a no-go area avoided on the
other side, and the rest of the run differs.  A least-squares fit on that surface stalls.
The log holds more than the track, though: it holds the set-point the back-seat gave at
every step.  So each run is cut into short segments (:data:`SEGMENT_STEPS` steps); each
segment starts from the logged state (position, heading, speed, turn rate; the sway is
rebuilt from the logged speed and turn rate) and is flown *open loop* on the logged
set-points through the simulator's own vehicle and tide models (:func:`sim.uuv.vehicle.
step_vehicle`, :func:`sim.uuv.environment.tidal_current`) under the trial bias.  The predicted
positions and energy used are compared with the logged ones.  No autonomy decision sits
inside the residual, so it is smooth in the bias, every log of every scenario counts,
and a truncated log counts as far as it goes.  Segments are short so that a real
vehicle's unmodelled disturbances do not accumulate.

:func:`fit_bias` minimises those residuals over the six bias parameters with
``scipy.optimize.least_squares`` (all segments of all logs in one vectorised batch) and
gives each parameter a standard error from the Jacobian at the solution,
``(J^T J)^-1 s^2`` with ``s^2`` the residual variance — or, when larger, the cluster-robust
(sandwich) estimate by segment, since an unmodelled current or navigation drift makes a
segment's residuals move together and the plain formula would then be optimistic.  A weak prior around neutral
(:data:`PRIOR_SD`) keeps a direction the logs barely inform (one run, one tide phase)
from wandering to a bound; a parameter the logs carry no information about at all (a
mission without current, say) stays neutral and is reported as not identifiable.  The fitted bias is then checked closed loop by :mod:`planner.compare`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from rapt.errors import InputError
from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, NEUTRAL, Bias
from sim.uuv.environment import tidal_current
from sim.uuv.mission import Mission
from sim.uuv.vehicle import SWAY_COUPLING, VehicleState, step_vehicle

__all__ = ["BiasFit", "fit_bias", "segment_batch", "SEGMENT_STEPS"]

#: Steps per open-loop segment (2 s steps: two minutes of flight).
SEGMENT_STEPS = 60
#: Residual units: metres of position, watt-hours of energy used.
SIGMA_POSITION_M = 1.0
SIGMA_ENERGY_WH = 0.05
#: A weak prior around neutral, one standard deviation per parameter: far wider than any
#: range day's bias, so informative logs are not pulled, but a direction the logs say
#: nothing about (one run, one tide phase: current scale against offset) stays put.
PRIOR_SD = {
    "speed": 0.5,
    "current_scale": 1.0,
    "current_offset": 1.0,
    "heading": 15.0,
    "battery": 1.0,
    "start_time": 3 * 3600.0,
}
#: Parameter scaling for the optimiser (a unit step of each is a comparable effect).
SCALE = {"speed": 0.1, "current_scale": 0.1, "current_offset": 0.1, "heading": 1.0, "battery": 0.1, "start_time": 600.0}


@dataclass
class Segments:
    """Open-loop segments of logged runs, as (N, L) arrays; ``valid`` masks padding."""

    start: dict  # x, y, heading, surge, sway, yaw_rate, energy_hj, t: (N,)
    t: np.ndarray  # (N, L) time of each step's start
    start_time: np.ndarray  # (N,) the scenario's start time (s after midnight)
    heading_cmd: np.ndarray
    speed_cmd: np.ndarray
    obs_x: np.ndarray  # (N, L) logged position after each step
    obs_y: np.ndarray
    obs_energy_wh: np.ndarray  # (N, L) energy used since the segment's start
    valid: np.ndarray
    run: np.ndarray  # (N,) index of the run each segment comes from


def _sway(steps: np.ndarray, mission: Mission) -> np.ndarray:
    """Sway rebuilt from logged surge and turn rate with the vehicle model's sway equation."""
    dt = mission.dt
    a_v = 1.0 - np.exp(-dt * mission.vehicle.sway_damping)
    v = np.zeros(steps.shape[0])
    for k in range(1, steps.shape[0]):
        u, r = steps[k, 6], steps[k, 7]
        v[k] = v[k - 1] + (-SWAY_COUPLING * u * r - v[k - 1]) * a_v
    return v


def segment_batch(mission: Mission, runs: list, start_times: list[float], length: int = SEGMENT_STEPS) -> Segments:
    """Cut every run (a :class:`planner.logs.LoggedRun`) into segments of ``length`` steps.

    A step counts when the next step follows it by exactly ``mission.dt`` (no gap from a
    lost chunk) and the set-point flown after it is in the log.
    """
    dt = mission.dt
    rows = []
    for i, (run, t0) in enumerate(zip(runs, start_times)):
        s, sp = run.steps, run.setpoints
        if s.shape[0] < 2:
            continue
        sway = _sway(s, mission)
        ok = (np.abs(np.diff(s[:, 0]) - dt) < 1e-6) & np.isfinite(sp[:-1, 1])
        k = 0
        while k < len(ok):
            if not ok[k]:
                k += 1
                continue
            end = k
            while end < len(ok) and ok[end] and end - k < length:
                end += 1
            rows.append((i, t0, k, end, s, sp, sway))
            k = end
    n = len(rows)
    L = length
    t = np.zeros((n, L))
    hc, sc = np.zeros((n, L)), np.zeros((n, L))
    ox, oy, oe = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    valid = np.zeros((n, L), dtype=bool)
    start = {key: np.zeros(n) for key in ("x", "y", "heading", "surge", "sway", "yaw_rate")}
    st, run_index = np.zeros(n), np.zeros(n, dtype=np.int64)
    for j, (i, t0, k, end, s, sp, sway) in enumerate(rows):
        m = end - k
        start["x"][j], start["y"][j], start["heading"][j] = s[k, 1], s[k, 2], s[k, 3]
        start["surge"][j], start["sway"][j], start["yaw_rate"][j] = s[k, 6], sway[k], s[k, 7]
        st[j], run_index[j] = t0, i
        t[j, :m] = s[k:end, 0]
        hc[j, :m], sc[j, :m] = sp[k:end, 0], sp[k:end, 1]
        ox[j, :m], oy[j, :m] = s[k + 1 : end + 1, 1], s[k + 1 : end + 1, 2]
        oe[j, :m] = (s[k + 1 : end + 1, 4] - s[k, 4]) / 36.0
        valid[j, :m] = True
    return Segments(start, t, st, hc, sc, ox, oy, oe, valid, run_index)


def replay(mission: Mission, seg: Segments, bias: Bias) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Predicted (x, y, energy used) of every segment step under ``bias``: (N, L) each."""
    n, L = seg.t.shape
    spec, dt = mission.vehicle, mission.dt
    s = VehicleState(
        seg.start["x"].copy(),
        seg.start["y"].copy(),
        seg.start["heading"].copy(),
        seg.start["surge"].copy(),
        seg.start["sway"].copy(),
        seg.start["yaw_rate"].copy(),
        np.zeros(n),
    )
    px, py, pe = np.zeros((n, L)), np.zeros((n, L)), np.zeros((n, L))
    course = np.deg2rad(bias.heading)
    for j in range(L):
        moving = seg.valid[:, j]
        ce, cn = tidal_current(
            mission.current, seg.start_time + bias.start_time + seg.t[:, j], bias.current_scale, bias.current_offset
        )
        step_vehicle(
            s,
            spec,
            seg.heading_cmd[:, j],
            seg.speed_cmd[:, j],
            ce,
            cn,
            dt,
            moving,
            speed_scale=bias.speed,
            course_bias=course,
            energy_scale=bias.battery,
        )
        px[:, j], py[:, j], pe[:, j] = s.x, s.y, -s.energy_wh
    return px, py, pe


@dataclass
class BiasFit:
    """The fitted bias with a standard error per parameter (None: not identifiable)."""

    bias: Bias
    stderr: dict[str, float | None]
    rms_position_m: float
    rms_energy_wh: float
    rms_position_neutral_m: float
    segments: int
    residuals: int
    runs: int
    success: bool
    message: str
    correlation: dict[str, dict[str, float]] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {name: {"estimate": float(getattr(self.bias, name)), "stderr": self.stderr[name]} for name in BIAS_NAMES}


def _residuals(mission: Mission, seg: Segments, bias: Bias) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    px, py, pe = replay(mission, seg, bias)
    v = seg.valid
    dx = (px - seg.obs_x)[v] / SIGMA_POSITION_M
    dy = (py - seg.obs_y)[v] / SIGMA_POSITION_M
    de = (pe - seg.obs_energy_wh)[v] / SIGMA_ENERGY_WH
    return dx, dy, de


def fit_bias(
    mission: Mission,
    runs: list,
    start_times: list[float],
    fit: tuple[str, ...] = BIAS_NAMES,
    length: int = SEGMENT_STEPS,
) -> BiasFit:
    """Fit the parameters ``fit`` (the others stay neutral) to all ``runs`` jointly."""
    seg = segment_batch(mission, runs, start_times, length)
    if not seg.valid.any():
        raise InputError(
            "LOGS: no replayable flight in the logs (no telemetry steps with set-points); the bias cannot be estimated"
        )
    names = [n for n in BIAS_NAMES if n in fit]
    scale = np.array([SCALE[n] for n in names])
    base = np.array([NEUTRAL[n] for n in names])
    lo = np.array([(BIAS_LIMITS[n][0] - NEUTRAL[n]) / SCALE[n] for n in names])
    hi = np.array([(BIAS_LIMITS[n][1] - NEUTRAL[n]) / SCALE[n] for n in names])

    def to_bias(p: np.ndarray) -> Bias:
        return Bias(**{n: float(v) for n, v in zip(names, base + scale * p)})

    prior = scale / np.array([PRIOR_SD[n] for n in names])
    weight = [0.0]  # the prior's rows, in units of the data's residual scale (set after a first fit)

    def fun(p: np.ndarray) -> np.ndarray:
        return np.concatenate([*_residuals(mission, seg, to_bias(p)), weight[0] * prior * p])

    p0 = np.zeros(len(names))
    r0 = _residuals(mission, seg, to_bias(p0))
    opts = dict(bounds=(lo, hi), method="trf", loss="soft_l1", f_scale=5.0, diff_step=1e-6, x_scale=1.0)
    sol = least_squares(fun, p0, max_nfev=200, **opts)  # the data alone
    m = sol.fun.size - len(names)
    s2 = float(sol.fun[:m] @ sol.fun[:m]) / max(m - len(names), 1)
    weight[0] = float(np.sqrt(s2))  # then the prior, weighed against the data's own noise
    sol = least_squares(fun, sol.x, max_nfev=100, **opts)
    J = sol.jac[:m]  # the data's Jacobian (the prior rows last)
    col = np.linalg.norm(J, axis=0)
    known = col > 1e-8 * max(col.max(), 1e-300)
    res = sol.fun[:m]
    s2 = float(res @ res) / max(m - int(known.sum()), 1)
    stderr: dict[str, float | None] = {n: None for n in BIAS_NAMES}
    correlation: dict[str, dict[str, float]] = {}
    if known.any():
        Jk = J[:, known]
        bread = np.linalg.pinv(Jk.T @ Jk / s2 + np.diag(prior[known] ** 2))
        # residuals within a segment are correlated (an unmodelled current displaces every later
        # step): a cluster-robust (sandwich) covariance by segment, and the larger of the two
        seg_of = np.nonzero(seg.valid)[0]
        groups = np.concatenate([seg_of, seg_of, seg_of])
        score = np.zeros((seg.valid.shape[0], Jk.shape[1]))
        np.add.at(score, groups, Jk * (res / s2)[:, None])
        robust = bread @ (score.T @ score) @ bread
        sd = np.sqrt(np.clip(np.maximum(np.diag(bread), np.diag(robust)), 0, None))
        kn = [n for n, ok in zip(names, known) if ok]
        for n, v, sc in zip(kn, sd, scale[known]):
            stderr[n] = float(v * sc)
        bsd = np.sqrt(np.clip(np.diag(bread), 1e-300, None))
        corr = bread / np.outer(bsd, bsd)
        correlation = {a: {b: float(corr[i, j]) for j, b in enumerate(kn) if b != a} for i, a in enumerate(kn)}
    p = np.where(known, sol.x, 0.0)
    for n in BIAS_NAMES:  # parameters left out of the fit stay neutral, exactly
        if n not in names:
            stderr[n] = 0.0
    best = to_bias(p)
    dx, dy, de = _residuals(mission, seg, best)
    return BiasFit(
        best,
        stderr,
        float(np.sqrt(np.mean(dx**2 + dy**2))) * SIGMA_POSITION_M,
        float(np.sqrt(np.mean(de**2))) * SIGMA_ENERGY_WH,
        float(np.sqrt(np.mean(r0[0] ** 2 + r0[1] ** 2))) * SIGMA_POSITION_M,
        int(seg.valid.shape[0]),
        int(m),
        int(len(set(seg.run.tolist()))),
        bool(sol.success),
        str(sol.message),
        correlation,
    )
