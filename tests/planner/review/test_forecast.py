"""Predictions that say how sure they are (planner.review.forecast), on the committed range2017 plan.

Fast: the forecasts are small seeded batches of the simulator; a range day "flown" here is the
batch simulator under the plan's own execution noise with another seed.  tests/cli/test_compare.py
checks the same on real SIL logs through ``rapt-plan compare``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.common.execution_noise import dithered_runs
from planner.common.plans import load_plan
from planner.common.scenarios import design_row, valid_design_rows
from planner.review.biasfit import BiasFit, bias_priors
from planner.review.forecast import (
    Ensemble,
    bias_draws,
    brier,
    brier_held,
    day_brier,
    ensemble,
    plan_noise,
    run_forecast,
)
from rapt.errors import InputError
from rapt.mapfit import MapEstimate
from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, NEUTRAL, Bias
from sim.uuv.scoring import MODE_NAMES

PLAN = Path(__file__).resolve().parents[3] / "field_plans" / "range2017"


@pytest.fixture(scope="module")
def plan():
    return load_plan(PLAN)


def fit_with(identified: dict[str, float], bias: Bias, corr: float = 0.0) -> BiasFit:
    """A bias fit whose ``identified`` parameters have these standard errors (correlated ``corr``), the rest not."""
    names = list(identified)
    sd = np.array([identified[n] for n in names])
    c = np.full((len(names), len(names)), corr) + (1 - corr) * np.eye(len(names))
    est = MapEstimate(
        priors=tuple(bias_priors()),
        value={n: float(getattr(bias, n)) for n in BIAS_NAMES},
        map_value={n: float(getattr(bias, n)) for n in BIAS_NAMES},
        stderr={n: identified.get(n, 1.0) for n in BIAS_NAMES},
        identified={n: n in identified for n in BIAS_NAMES},
        noise_scale={},
        residuals=100,
        success=True,
        message="",
        covariance=c * np.outer(sd, sd),
    )
    return BiasFit(bias, est, 1.0, 0.01, 10.0, 10, 100, 3)


def test_the_brier_scores_by_hand():
    # two runs: a forecast split evenly between TF and SS when TF showed, and one sure of MS when MS showed
    assert brier([np.array([0.5, 0.5, 0, 0]), np.array([0, 0, 1.0, 0])], ["TF", "MS"]) == pytest.approx(0.25)
    # a deterministic prediction that is wrong scores 2, one that is right 0
    assert brier([np.array([0, 1.0, 0, 0]), np.array([1.0, 0, 0, 0])], ["TF", "TF"]) == pytest.approx(1.0)
    # "the predicted mode held" forecast at 0.8 and held, at 0.3 and did not: ((0.2)^2 + (0.3)^2) / 2
    assert brier_held([0.8, 0.3], [True, False]) == pytest.approx(0.065)
    assert brier([], []) is None and brier_held([], []) is None


def test_both_sides_of_a_pair_count_only_in_the_same_draw():
    scores = np.zeros((2, 4, 1))
    scores[0, :, 0] = [1, 1, 0, 0]  # side a shows its outcome in draws 0 and 1
    scores[1, :, 0] = [1, 0, 1, 0]  # side b in draws 0 and 2
    e = Ensemble(["a", "b"], scores, np.ones((2, 4), dtype=bool), np.zeros((2, 4), dtype=int))
    got = e.p_both("a", "b", [0], np.array([1.0]), np.array([1.0]))
    assert got == {"p_straddles": 0.25, "p_sides": [0.5, 0.5]}


def test_forecasts_are_distributions_and_the_same_seed_gives_the_same_numbers(plan):
    ids = ["pair1a", "pair3a"]
    U = np.array([plan.u(s) for s in ids])
    sigma = plan_noise(plan)
    fit = fit_with({"speed": 0.03, "current_offset": 0.05}, Bias(speed=1.1, current_offset=0.2), corr=0.5)
    draws = bias_draws(fit, fit.bias, 24, seed=3)
    one = ensemble(plan.mission, ids, U, sigma, 24, 3, bias=draws)
    again = ensemble(plan.mission, ids, U, sigma, 24, 3, bias=bias_draws(fit, fit.bias, 24, seed=3))
    other = ensemble(plan.mission, ids, U, sigma, 24, 4, bias=bias_draws(fit, fit.bias, 24, seed=4))
    for sid in ids:
        p = one.distribution(sid)
        assert p is not None and p.shape == (len(MODE_NAMES),) and p.sum() == pytest.approx(1.0) and p.min() >= 0
        np.testing.assert_array_equal(p, again.distribution(sid))
    np.testing.assert_array_equal(one.scores, again.scores)
    assert not np.array_equal(np.nan_to_num(one.scores), np.nan_to_num(other.scores))


def test_a_scenario_far_from_any_boundary_is_forecast_near_certain(plan):
    """Far: its mode holds when any noisy coordinate moves three sigmas either way."""
    m, sigma = plan.mission, plan_noise(plan)
    rows = valid_design_rows(m, 12)
    U = np.array([design_row(m, i) for i in rows])
    noisy = np.flatnonzero(sigma > 0)
    step = np.eye(m.dim)[noisy] * 3 * sigma  # one row per noisy coordinate: three sigmas along it
    moves = np.concatenate([step, -step])
    X = np.clip(U[:, None, :] + moves[None, :, :], 0, 1).reshape(-1, m.dim)
    centre, moved = sim.uuv.simulate(m, U), sim.uuv.simulate(m, X)
    same = (moved.modes.reshape(len(rows), -1) == centre.modes[:, None]).all(axis=1)
    assert same.any(), "no design row far from a boundary among the first 12"
    k = int(np.argmax(same))
    e = ensemble(m, ["far"], U[k][None, :], sigma, 40, 0)
    p = e.distribution("far")
    assert p is not None and p[centre.modes[k]] >= 0.95, p


def test_the_noise_forecast_is_the_plans_own_dithering(plan):
    """Near a boundary the forecast is no coin it does not know about: it agrees with the plan's P(mode)."""
    ids = ["pair1a", "pair4b"]  # 0.61 and 0.598 in the plan's 1,000 dithers
    e = ensemble(plan.mission, ids, np.array([plan.u(s) for s in ids]), plan_noise(plan), 100, 0)
    for sid in ids:
        s = plan.scenario(sid)
        p = e.distribution(sid)[MODE_NAMES.index(s["predicted"]["mode"])]
        assert abs(p - s["dithering"]["p_predicted_mode"]) < 0.15, (sid, p)  # 3 binomial s.e. at 100 draws
        assert p < 0.8  # and it is far from sure


def test_bias_draws_vary_only_identified_parameters_within_their_limits():
    centre = Bias(speed=1.95, heading=3.0)
    fit = fit_with({"speed": 0.2, "heading": 1.0}, centre)
    d = bias_draws(fit, centre, 200, seed=1)
    assert d["speed"][0] == 1.95 and d["heading"][0] == 3.0  # the first draw is the bias itself
    assert d["speed"].max() <= BIAS_LIMITS["speed"][1] and (d["speed"] == BIAS_LIMITS["speed"][1]).any()
    assert d["heading"].std() == pytest.approx(1.0, rel=0.2)
    for name in ("current_scale", "current_offset", "battery", "start_time"):
        assert np.all(d[name] == NEUTRAL[name])  # not identified: held at the fit's value
    np.testing.assert_array_equal(d["heading"], bias_draws(fit, centre, 200, seed=1)["heading"])


@pytest.mark.parametrize("bias", [Bias(), Bias(speed=1.1, current_offset=0.2)], ids=["unbiased", "biased"])
def test_a_day_with_execution_noise_is_scored_better_by_the_forecast_than_by_one_prediction(plan, bias):
    """Every plan scenario flown five times under ``bias``, each run off plan by the plan's execution noise
    (seed 99); the bias known to the fit within a small standard error.  The corrected forecast's Brier
    score beats the corrected deterministic prediction's, in modes and in "held"."""
    m, sigma = plan.mission, plan_noise(plan)
    ids = [s["id"] for s in plan.scenarios]
    U = np.array([plan.u(s) for s in ids])
    _, day = dithered_runs(m, U, 6, sigma, seed=99, bias=bias)
    flown = day.modes.reshape(len(ids), 6)[:, 1:]  # the first dither is the plan's own row: not a day's run
    ok = day.valid.reshape(len(ids), 6)[:, 1:]
    used = not bias.is_neutral
    fit = fit_with({"speed": 0.01, "current_offset": 0.02} if used else {}, bias)
    noise = ensemble(m, ids, U, sigma, 60, 0)
    biased = ensemble(m, ids, U, sigma, 60, 0, bias=bias_draws(fit, bias, 60, 0)) if used else noise
    corrected = sim.uuv.simulate(m, U, bias=bias)
    rows = []
    for k, sid in enumerate(ids):
        planned = plan.scenario(sid)["predicted"]["mode"]
        det = {"planned": planned, "uncorrected": planned, "corrected": MODE_NAMES[corrected.modes[k]]}
        for mode in flown[k][ok[k]]:
            obs = MODE_NAMES[mode]
            rows.append({"observed_mode": obs, "predicted_mode": planned})
            rows[-1]["forecast"] = run_forecast(noise, biased, sid, obs, det, used=used)
    b = day_brier(rows, corrected_used=used)
    assert b["runs"] == int(ok.sum()) >= 40
    assert b["corrected"] == b["bias_noise" if used else "noise"]
    for kind in ("mode", "held"):
        assert b["corrected"][kind] < b["deterministic_corrected"][kind], b
        assert b["corrected"][kind] < b["deterministic_uncorrected"][kind], b


def test_a_plan_without_its_execution_noise_is_one_line(plan, tmp_path):
    data = dict(plan.data)
    data["study"] = {k: v for k, v in data["study"].items() if k != "dithering"}
    bare = type(plan)(data, tmp_path / "plan.json", plan.mission, plan.mission_file, plan.id)
    with pytest.raises(InputError, match=r"study\.dithering\.sigma_u .* regenerate the plan"):
        plan_noise(bare)
