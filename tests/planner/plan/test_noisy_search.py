"""``--noisy-search``: the search runs stochastic, tells S-NDV continuous metrics, repeats per seed and resumes."""

import json
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

import planner
import sim.uuv
from planner.plan.analysis import analyse
from planner.plan.generate import GenerateConfig, generate, search_mission
from planner.plan.noisy_search import NoisyMissionScores, noisy_columns
from rapt.errors import InputError, StudyMismatchError
from sim.uuv.metrics import metric_names

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
SCHEMA = json.loads((Path(planner.__file__).parent / "plan.schema.json").read_text())


@pytest.fixture(scope="module")
def range2017():
    return sim.uuv.load_mission(EXAMPLES / "range2017.toml")


def noisy(store: Path, **kw) -> GenerateConfig:
    base: dict[str, Any] = dict(budget=300, batch_size=100, global_fraction=0.5, store=store, noisy_search=True)
    return GenerateConfig(**(base | kw))


def test_the_steered_columns_are_the_modes_then_continuous_metrics(range2017):
    cols, types = noisy_columns(range2017)
    names = metric_names(range2017)
    assert cols[:2] == [0, 1] and types[:2] == ("binary", "binary")
    steered = [names[c] for c in cols[2:]]
    assert set(types[2:]) == {"continuous"} and {"mission.battery_left", "mission.time_s"} <= set(steered)
    assert {"area.A.closest_m", "nogo.NG.closest_m", "waypoint.0.closest_m"} <= set(steered)


def test_noisy_search_runs_stochastic_and_tells_the_sampler_continuous_outputs(range2017, tmp_path):
    study = search_mission(range2017, noisy(tmp_path / "a.db"))
    cols, types = noisy_columns(range2017)
    assert study.output_types == types and study.sampler.Y.shape[1] == len(cols)
    told = study.sampler.Y[:, 2:]
    assert np.unique(told).size > 50  # continuous values steer, not only pass/fail
    rows = study.X[:40]
    stochastic = sim.uuv.simulate(range2017, rows, seed=0, stochastic=True).scores
    np.testing.assert_array_equal(study.Y[:40], stochastic)  # every score stored, as the stochastic runs give it
    assert not np.array_equal(stochastic, sim.uuv.simulate(range2017, rows).scores)
    assert not np.array_equal(stochastic, NoisyMissionScores(range2017, 1)(rows))  # the seed drives the noise
    analyse(range2017, study, stochastic_seed=0)  # the spot check re-runs them stochastic
    with pytest.raises(StudyMismatchError):
        analyse(range2017, study)  # a deterministic re-run would not match


def test_same_seed_same_study_and_a_stopped_study_resumes_to_it(range2017, tmp_path):
    whole = search_mission(range2017, noisy(tmp_path / "whole.db"))

    def kill(done: int, total: int) -> None:
        if done >= 200:
            raise KeyboardInterrupt  # killed after two of three batches, both stored

    with pytest.raises(KeyboardInterrupt):
        search_mission(range2017, noisy(tmp_path / "part.db"), progress=kill)
    resumed = search_mission(range2017, noisy(tmp_path / "part.db"))
    np.testing.assert_array_equal(whole.X, resumed.X)
    np.testing.assert_array_equal(whole.Y, resumed.Y)
    other = search_mission(range2017, noisy(tmp_path / "other.db", seed=1))
    assert not np.array_equal(whole.X, other.X)
    with pytest.raises(StudyMismatchError):  # a deterministic search does not continue a noisy study
        search_mission(range2017, noisy(tmp_path / "whole.db", noisy_search=False))


@pytest.mark.parametrize("kw, named", [({"refine": 40}, "--refine"), ({"surrogate_file": "s.npz"}, "--surrogate")])
def test_noisy_search_refuses_the_searches_of_a_deterministic_model(tmp_path, kw, named):
    with pytest.raises(InputError, match=f"--noisy-search.*{named}"):
        noisy(tmp_path / "x.db", **kw).check()


def test_the_plan_records_which_search_made_it(tmp_path):
    mission = sim.uuv.load_mission(EXAMPLES / "imitation7.toml")
    cfg = noisy(tmp_path / "s.db", budget=200, dithers=20, pairs=2)
    plan = generate(mission, EXAMPLES / "imitation7.toml", tmp_path / "out", cfg)
    jsonschema.Draft202012Validator(SCHEMA).validate(json.loads((tmp_path / "out" / "plan.json").read_text()))
    assert plan["study"]["search"]["model"] == "stochastic"
    assert plan["study"]["search"]["steered_on"][:2] == ["mission_success", "safety_success"]
    assert len(plan["study"]["search"]["steered_on"]) > 2
