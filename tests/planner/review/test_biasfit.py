"""The execution-bias fit knows what the logs can tell, and a correction is checked before it is used.

Runs come straight from the batch simulator (bit-exact with lock-step SIL,
:mod:`tests.support.simlogs`); tests/cli/test_compare.py does the same on real logs.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import sim.uuv
from planner.review.biasfit import END_MISMATCH_LOGLIK, PRIORS, check_end_conditions, end_condition_loglik, fit_bias
from planner.review.correction import NO_SUPPORT, correction_support, cross_validate
from planner.review.runs import CompareConfig, Observation
from sim.uuv.bias import Bias, parse_bias
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import mode_name
from tests.sim.uuv.test_simulate import EXAMPLES
from tests.support.simlogs import sim_runs

MISSION = sim.uuv.load_mission(EXAMPLES / "range2017.toml")


def scenarios(mission, n: int, seed: int = 1) -> np.ndarray:
    U = np.random.default_rng(seed).random((10 * n, mission.dim))
    return U[make_scenarios(mission, U).valid][:n]


def start_times(mission, U) -> list[float]:
    return [float(t) for t in make_scenarios(mission, U).start_time]


def test_an_injected_speed_is_recovered_and_identified():
    U = scenarios(MISSION, 3)
    fit = fit_bias(MISSION, sim_runs(MISSION, U, bias=parse_bias("speed=1.15")), start_times(MISSION, U), bootstrap=0)
    d = fit.to_dict()
    assert d["speed"]["identified"] and d["speed"]["estimate"] == pytest.approx(1.15, abs=1e-3)
    assert d["speed"]["prior"] == {"centre": 1.0, "sd": PRIORS["speed"].sd}


def test_a_parameter_the_logs_cannot_see_stays_neutral_and_says_so():
    # no tide at all: its scale and its clock change nothing the vehicle does
    still = dataclasses.replace(MISSION, current=dataclasses.replace(MISSION.current, speed=0.0))
    U = scenarios(still, 3)
    fit = fit_bias(still, sim_runs(still, U, bias=parse_bias("speed=1.1")), start_times(still, U), bootstrap=0)
    d = fit.to_dict()
    for name in ("current_scale", "start_time"):
        assert not d[name]["identified"], name
        assert d[name]["estimate"] == Bias().to_dict()[name]  # exactly neutral for prediction
        assert fit.bias.to_dict()[name] == Bias().to_dict()[name]
    assert d["speed"]["identified"] and d["speed"]["estimate"] == pytest.approx(1.1, abs=1e-3)


def test_one_noisy_log_does_not_invent_a_clock_error():
    # the user: one log's start_time s.e. is thousands of seconds; it must stay neutral
    U = scenarios(MISSION, 1)
    runs = sim_runs(MISSION, U, bias=parse_bias("speed=1.15"), stochastic=True, seed=4)
    fit = fit_bias(MISSION, runs, start_times(MISSION, U), bootstrap=20)
    d = fit.to_dict()
    assert not d["start_time"]["identified"] and d["start_time"]["estimate"] == 0.0
    assert d["speed"]["identified"] and abs(d["speed"]["estimate"] - 1.15) <= 0.2 * 0.15


@pytest.mark.slow
def test_standard_errors_cover_the_truth_with_drift_and_an_unmodelled_current():
    U = scenarios(MISSION, 6)
    injected = parse_bias("speed=1.15,current_offset=0.3")
    runs = sim_runs(MISSION, U, bias=injected, stochastic=True, seed=1)
    fit = fit_bias(MISSION, runs, start_times(MISSION, U), bootstrap=30, seed=1)
    for name, v in fit.to_dict().items():
        if v["identified"]:
            assert abs(v["estimate"] - getattr(injected, name)) <= 3 * v["stderr"], (name, v)
    assert fit.identified["speed"] and fit.identified["current_offset"]


def test_an_end_condition_the_bias_does_not_reproduce_counts_against_it():
    names = ["mission.return_reason", "collisions", "transmission", "recovery", "mission_success", "mission.time_s"]
    observed = np.array([[1.0, 0.0, 1.0, 1.0, 1.0, 3000.0]])
    same = observed[None].copy()
    later = observed[None].copy()
    later[..., -1] += 60.0
    fuel = observed[None].copy()
    fuel[..., 0] = 2.0
    ll = end_condition_loglik(names, np.concatenate([same, later, fuel]), observed)
    assert ll[0, 0] == 0.0 and ll[1, 0] == pytest.approx(-0.5) and ll[2, 0] == END_MISMATCH_LOGLIK


def test_with_exact_logs_the_estimate_reproduces_every_logged_end():
    U = scenarios(MISSION, 3)
    runs = sim_runs(MISSION, U, bias=parse_bias("speed=1.15"))
    st = start_times(MISSION, U)
    fit = fit_bias(MISSION, runs, st, bootstrap=0)
    checked = check_end_conditions(MISSION, fit, runs, st, U, [r.scores for r in runs], candidates=4)
    assert checked.end_conditions["chosen"] == "estimate"
    assert checked.end_conditions["ends_reproduced_by_chosen"] == 3


def observations(runs, U) -> list[Observation]:
    return [Observation(r, f"s{k}", U[k], r.scores, mode_name(r.scores)) for k, r in enumerate(runs)]


def held_out(bias: str, n: int = 3) -> dict:
    U = scenarios(MISSION, n, seed=5)
    pred = sim.uuv.simulate(MISSION, U, trajectories=True)
    runs = sim_runs(MISSION, U, bias=parse_bias(bias))
    rows = {f"s{k}": k for k in range(n)}
    return cross_validate(MISSION, observations(runs, U), start_times(MISSION, U), pred, rows, CompareConfig())


def test_a_correction_that_predicts_held_out_runs_better_is_used():
    cv = held_out("speed=1.15")
    assert len(cv["folds"]) == 3
    path = cv["held_out_path_error_m"]
    assert path["corrected"] < 0.01 * path["uncorrected"]
    assert cv["held_out_mode_agreement"]["corrected"] == 1.0
    assert cv["correction_used"] and cv["note"].startswith("correction used")


def test_a_correction_that_does_not_help_is_not_used():
    cv = held_out("none")  # the vehicle is the model: nothing to correct
    assert not cv["correction_used"]
    assert cv["note"].startswith(NO_SUPPORT)


@pytest.mark.parametrize(
    ("agree_u", "agree_c", "path_u", "path_c", "used"),
    [
        (0.5, 1.0, 30.0, 1.0, True),  # better in both
        (1.0, 1.0, 30.0, 1.0, True),  # modes as good, paths better
        (1.0, 0.8, 30.0, 1.0, False),  # a better path never excuses worse modes
        (0.8, 0.8, 30.0, 29.0, False),  # within noise: not worth it
        (None, None, None, None, False),  # nothing held out
    ],
)
def test_the_rule_uses_a_correction_only_on_held_out_evidence(agree_u, agree_c, path_u, path_c, used):
    assert correction_support(agree_u, agree_c, path_u, path_c)[0] is used
