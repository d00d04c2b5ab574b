"""Logs whose report times jitter, or lose a report, replay step by step (issue 38, item 4).

A continuously moving vehicle (0.1 s physics) flies the set-points of simulated runs and
is logged as a vehicle-paced log holds it, at report times that land on the decision
period (2 s) or ±0.25 s off it.  The replay must keep every jittered step, lose only the
steps a missing report spans, and fit the same execution bias from both logs.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.review.biasfit import fit_bias
from planner.review.segments import MAX_STEP_SHARE, replay, replayable_steps, segment_batch
from sim.uuv.bias import Bias
from sim.uuv.environment import tidal_current
from sim.uuv.scenario import make_scenarios
from sim.uuv.vehicle import VehicleState, step_vehicle
from tests.support.simlogs import sim_runs

ROOT = Path(__file__).resolve().parents[3]
MISSION = ROOT / "examples" / "range2017.toml"
JITTER_S = 0.25
STEPS = 400
BIAS = Bias(speed=1.15, current_offset=0.3)


@pytest.fixture(scope="module")
def mission():
    return sim.uuv.load_mission(MISSION)


@pytest.fixture(scope="module")
def flown(mission):
    X = np.random.default_rng(3).random((8, mission.dim))
    U = X[make_scenarios(mission, X).valid][:2]
    return sim_runs(mission, U), list(make_scenarios(mission, U).start_time)


def logged_at(mission, run, t0: float, times: np.ndarray, bias: Bias = BIAS, substep: float = 0.1):
    """What a vehicle-paced log holds when a biased vehicle flies ``run``'s set-points continuously and reports
    at ``times`` (scenario seconds), each report's set-point flown until the next report: positions to the
    centimetre, energy in whole hectojoules, ground speed in the speed column."""
    n = len(times)
    s, sp = np.zeros((n, run.steps.shape[1])), run.setpoints[:n].copy()
    s[:, 0] = times
    v = VehicleState.at_rest(run.steps[:1, 1], run.steps[:1, 2], run.steps[:1, 3], np.array([1000.0]))
    s[0, 1:4], s[0, 4] = (v.x[0], v.y[0], v.heading[0]), 0.0
    one = np.ones(1, dtype=bool)
    for k in range(n - 1):
        h = times[k + 1] - times[k]
        m = math.ceil(h / substep - 1e-9)
        x0, y0 = v.x[0], v.y[0]
        for q in range(m):
            ce, cn = tidal_current(mission.current, t0 + times[k] + q * h / m, 1.0, bias.current_offset)
            step_vehicle(v, mission.vehicle, sp[k, :1], sp[k, 1:2], ce, cn, h / m, one, speed_scale=bias.speed)
        s[k + 1, 1:4] = np.round(v.x[0], 2), np.round(v.y[0], 2), v.heading[0]
        s[k + 1, 4] = np.floor((1000.0 - v.energy_wh[0]) * 36.0)
        s[k + 1, 6], s[k + 1, 7] = np.hypot(v.x[0] - x0, v.y[0] - y0) / h, v.yaw_rate[0]
    return dataclasses.replace(run, steps=s, setpoints=sp, meta={**run.meta, "pacing": "vehicle"})


def report_times(dt: float, n: int, jitter: float, seed: int) -> np.ndarray:
    """Decision-period report times, each moved by a uniform draw in ±``jitter`` (the first stays at 0)."""
    t = np.arange(n) * dt + np.random.default_rng(seed).uniform(-jitter, jitter, n)
    t[0] = 0.0
    return np.round(t, 3)  # time_boot_ms


@pytest.fixture(scope="module")
def logs(mission, flown):
    runs, starts = flown
    exact = [logged_at(mission, r, t0, np.arange(STEPS) * mission.dt) for r, t0 in zip(runs, starts)]
    times = [report_times(mission.dt, STEPS, JITTER_S, seed) for seed in range(len(runs))]
    jittered = [logged_at(mission, r, t0, t) for r, t0, t in zip(runs, starts, times)]
    return exact, jittered, starts


def test_every_jittered_step_is_replayed_over_its_own_length(mission, logs):
    exact, jittered, starts = logs
    for run in jittered:
        gaps = np.diff(run.steps[:, 0])
        assert np.mean(np.abs(gaps - mission.dt) < 1e-6) < 0.01  # hardly a step dt apart: the old rule kept none
        assert replayable_steps(run, mission.dt).all()
    seg = segment_batch(mission, jittered, starts)
    assert int(seg.valid.sum()) == sum(r.steps.shape[0] - 1 for r in jittered)
    assert seg.step_dt is not None and not np.allclose(seg.step_dt[seg.valid], mission.dt)
    # replayed under the true bias, jittered steps are predicted as well as exact ones
    rms = []
    for runs in (exact, jittered):
        s = segment_batch(mission, runs, starts)
        px, py, _, _ = replay(mission, s, BIAS)
        rms.append(float(np.sqrt(np.mean(((px - s.obs_x) ** 2 + (py - s.obs_y) ** 2)[s.valid]))))
    assert rms[1] < 1.1 * rms[0], rms  # (the replay's sub-steps and start surge, not the jitter, set both)
    # each step flown for dt instead of its own length, the same jittered log is predicted worse
    fixed = dataclasses.replace(seg, step_dt=None)
    px, py, _, _ = replay(mission, fixed, BIAS)
    assert np.sqrt(np.mean(((px - seg.obs_x) ** 2 + (py - seg.obs_y) ** 2)[seg.valid])) > 1.05 * rms[1]


def test_a_missing_report_costs_the_step_it_spans_not_the_log(mission, logs):
    _, jittered, starts = logs
    run = jittered[0]
    keep = np.ones(run.steps.shape[0], dtype=bool)
    keep[[50, 51, 120, 300]] = False  # a step of 3 periods, two of 2: longer than the share allowed
    cut = dataclasses.replace(run, steps=run.steps[keep], setpoints=run.setpoints[keep])
    lengths = np.diff(cut.steps[:, 0])
    assert (np.abs(lengths - mission.dt) > MAX_STEP_SHARE * mission.dt).sum() == 3
    ok = replayable_steps(cut, mission.dt)
    assert ok.sum() == len(ok) - 3
    seg = segment_batch(mission, [cut], starts[:1])
    assert int(seg.valid.sum()) == len(ok) - 3
    assert seg.step_dt[seg.valid].max() < (1 + MAX_STEP_SHARE) * mission.dt


def test_jittered_and_exact_logs_give_the_same_bias_within_one_standard_error(mission, logs):
    exact, jittered, starts = logs
    a = fit_bias(mission, exact, starts, bootstrap=0)
    b = fit_bias(mission, jittered, starts, bootstrap=0)
    for name in ("speed", "current_offset", "heading"):  # what the positions carry
        assert a.identified[name] and b.identified[name], name
        va, vb = getattr(a.bias, name), getattr(b.bias, name)
        assert abs(vb - va) < a.stderr[name], (name, va, vb, a.stderr[name])
        # (a crab and a current across the flood both set the track sideways: fitted together, the crab
        # comes back within 0.05 degrees, a hundredth of its prior s.d.)
        tol = 0.05 if name == "heading" else 0.02 * max(1.0, abs(getattr(BIAS, name)))
        assert abs(vb - getattr(BIAS, name)) < tol, (name, vb)
    # the energy counter's whole hectojoules fall elsewhere on jittered steps: 1.6 s.e. here, 0.05 % of the value
    assert abs(b.bias.battery - a.bias.battery) < 1e-3 and abs(b.bias.battery - 1.0) < 1e-3
