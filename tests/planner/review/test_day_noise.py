"""The day's execution noise fitted to the logs (planner.review.day_noise), and the reliability table."""

from __future__ import annotations

import copy
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from planner.common.execution_noise import coordinate_kinds
from planner.common.plans import load_plan
from planner.review.day_noise import MAX_SIGMA_SHARE, PRIOR_WEIGHT, fit_day_noise
from planner.review.forecast import plan_noise, reliability
from planner.review.logs import STEP_FIELDS, LoggedRun
from planner.review.runs import Observation, PlanRuns, predict_plan
from sim.uuv.interface import HJ_PER_WH
from sim.uuv.scoring import MODE_NAMES

PLAN = Path(__file__).resolve().parents[3] / "field_plans" / "range2017"


@pytest.fixture(scope="module")
def day():
    plan = load_plan(PLAN)
    ids, U, pred = predict_plan(plan)
    return plan, PlanRuns(ids, U, pred, pred)


def _recovered(runs, sid) -> bool:
    return runs.corr.scores[runs.row_of[sid], runs.corr.names.index("recovery")] == 1


def _logged(plan, runs, sid, rng, position_m, late_s, battery_pct, recovered=True):
    """A log of scenario ``sid`` that strays from its replay by the given noise (and, unless ``recovered``,
    ends elsewhere than the recovery point)."""
    k = runs.row_of[sid]
    traj = runs.corr.trajectory(k)
    n = traj.shape[0]
    steps = np.zeros((n, len(STEP_FIELDS)))
    steps[:, 0] = traj[:, 0] + np.linspace(0.0, late_s, n)
    steps[:, 1:3] = traj[:, 1:3] + position_m * rng.standard_normal((n, 2))
    steps[:, 3] = traj[:, 3]
    steps[:, 4] = traj[:, 4] + battery_pct / 100 * plan.mission.vehicle.battery_wh * HJ_PER_WH
    run = LoggedRun(Path(f"{sid}.mcap"), {}, steps, np.full((n, 3), np.nan), "recovered", [], 0, True)
    scores = runs.corr.scores[k].copy()
    if not recovered:
        scores[runs.corr.names.index("recovery")] = 0.0
    return Observation(run, sid, runs.U[k], scores, MODE_NAMES[runs.corr.modes[k]])


def test_a_calm_day_fits_below_the_assumed_noise_and_the_prior_weighs_as_two_runs(day):
    plan, runs = day
    rng = np.random.default_rng(0)
    obs = [_logged(plan, runs, sid, rng, 3.0, 6.0, 0.2) for sid in runs.ids[:8]]
    noise = fit_day_noise(plan, obs, runs, plan_noise(plan))
    assert noise.prior == {"position": 10.0, "time": 30.0, "battery": 1.0}
    timed = sum(_recovered(runs, sid) for sid in runs.ids[:8])  # only runs recovered in the replay count for timing
    assert 0 < timed <= 8
    assert noise.runs == {"position": 8, "time": timed, "battery": 8}
    assert noise.observed_rms["position"] == pytest.approx(3.0, rel=0.1)
    assert noise.observed_rms["time"] == pytest.approx(6.0, rel=1e-6)
    assert noise.observed_rms["battery"] == pytest.approx(0.2, rel=1e-3)
    w, n = PRIOR_WEIGHT, timed
    assert noise.fitted["time"] == pytest.approx(math.sqrt((w * 30**2 + n * 6**2) / (w + n)), rel=1e-6)
    assert noise.fitted["position"] < 6.0
    kinds = coordinate_kinds(plan.mission)
    prior = plan_noise(plan)
    for c, kind in enumerate(kinds):
        if kind is None:
            assert noise.sigma_u[c] == prior[c]
        else:
            assert noise.sigma_u[c] == pytest.approx(prior[c] * noise.fitted[kind] / noise.prior[kind])
    assert "position 10 ->" in noise.note and "from 8 run(s)" in noise.note and f"from {timed} run(s)" in noise.note


def test_a_rough_day_fits_above_it_within_the_plans_limit(day):
    plan, runs = day
    rng = np.random.default_rng(1)
    obs = [_logged(plan, runs, sid, rng, 40.0, 200.0, 5.0) for sid in runs.ids[:10]]
    noise = fit_day_noise(plan, obs, runs, plan_noise(plan))
    assert noise.fitted["position"] > 30 and noise.fitted["time"] > 150 and noise.fitted["battery"] > 4
    assert np.all(noise.sigma_u <= MAX_SIGMA_SHARE) and np.all(noise.sigma_u >= plan_noise(plan))


def test_a_run_that_did_not_end_at_recovery_does_not_count_for_timing_and_no_run_leaves_the_prior(day):
    plan, runs = day
    rng = np.random.default_rng(2)
    sid = next(s for s in runs.ids if _recovered(runs, s))
    obs = [_logged(plan, runs, sid, rng, 3.0, 500.0, 0.2, recovered=False)]
    noise = fit_day_noise(plan, obs, runs, plan_noise(plan))
    assert noise.runs["time"] == 0 and noise.fitted["time"] == 30.0
    assert fit_day_noise(plan, [], runs, plan_noise(plan)).fitted == noise.prior


def test_a_plan_with_one_unit_cube_sigma_keeps_its_noise(day):
    plan, runs = day
    unit = copy.copy(plan)
    unit.data = copy.deepcopy(plan.data)
    unit.data["study"]["dithering"]["expected"] = {"unit": 0.02}
    noise = fit_day_noise(unit, [], runs, plan_noise(plan))
    assert np.array_equal(noise.sigma_u, plan_noise(plan)) and "unit-cube" in noise.note


def test_the_reliability_table_by_hand():
    rows = reliability([0.05, 0.1, 0.5, 0.9, 0.95, 1.0], [False, True, True, True, True, False])
    assert [r["runs"] for r in rows] == [2, 0, 1, 0, 3]
    assert rows[0]["mean_p"] == pytest.approx(0.075) and rows[0]["held"] == pytest.approx(0.5)
    assert rows[1]["mean_p"] is None and rows[4]["held"] == pytest.approx(2 / 3)


def test_a_run_late_along_its_path_is_off_in_time_not_in_position_and_one_beside_it_is(day):
    """Position noise is the distance from the predicted *path*: a vehicle a minute behind on it crosses no
    place the plan dithers (a start, a no-go area), one 20 m beside it does."""
    plan, runs = day
    rng = np.random.default_rng(3)
    late, beside = [], []
    for sid in runs.ids[:6]:
        o = _logged(plan, runs, sid, rng, 0.0, 0.0, 0.0)
        traj = runs.corr.trajectory(runs.row_of[sid])
        t = o.run.steps[:, 0]
        behind = o.run.steps.copy()
        behind[:, 1] = np.interp(t - 60.0, traj[:, 0], traj[:, 1])
        behind[:, 2] = np.interp(t - 60.0, traj[:, 0], traj[:, 2])
        late.append(dataclasses.replace(o, run=dataclasses.replace(o.run, steps=behind)))
        moved = o.run.steps.copy()
        moved[:, 1] += 20.0 * np.cos(np.deg2rad(30.0))
        moved[:, 2] += 20.0 * np.sin(np.deg2rad(30.0))
        beside.append(dataclasses.replace(o, run=dataclasses.replace(o.run, steps=moved)))
    behind_fit = fit_day_noise(plan, late, runs, plan_noise(plan), prior_weight=0.0)
    assert behind_fit.observed_rms["position"] < 2.0  # a time-matched distance: about 60 s x 1 m/s
    beside_fit = fit_day_noise(plan, beside, runs, plan_noise(plan), prior_weight=0.0)
    assert 5.0 < beside_fit.observed_rms["position"] <= 20.0
