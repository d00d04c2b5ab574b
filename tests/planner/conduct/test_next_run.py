"""The afternoon's decision (planner.conduct.next_run.decide) on a small plan, from runs given as outcomes."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

import planner
from planner.common.plans import load_plan
from planner.conduct.next_run import afternoon, decide
from planner.review.confirmations import RunOutcome, side_scenarios
from tests.support.small_plan import plan_copy

SCHEMA = json.loads((Path(planner.__file__).parent / "plan.schema.json").read_text())


def _valid(plan_file: Path) -> None:
    """The plan as next rewrote it still follows plan.schema.json."""
    jsonschema.Draft202012Validator(SCHEMA).validate(json.loads(plan_file.read_text()))


@pytest.fixture
def plan_dir(small_plan_dir):
    return small_plan_dir


def _outcome(day, sid: str) -> RunOutcome:
    return RunOutcome(sid, np.asarray(day.predicted[sid]), f"{sid}.mcap")


def test_a_side_that_came_out_against_is_flown_again_or_moved_into_the_plan(plan_dir, tmp_path):
    work = plan_copy(plan_dir, tmp_path / "plan")
    plan = load_plan(work)
    before = plan.id
    day = afternoon(plan, [])
    (a1, b1), (a2, b2) = (p["scenarios"] for p in plan.pairs)
    wrong = RunOutcome(b1, np.asarray(day.predicted[a1]), "miss.mcap")  # side b showed side a's outcome, twice
    runs = [_outcome(day, a1), wrong, wrong, _outcome(day, a2), _outcome(day, b2)]
    answer = decide(afternoon(plan, runs), 4)
    assert [p["status"] for p in answer["pairs"]][1] == "confirmed"
    assert answer["confirmation"][0]["sides"][1]["status"] == "against"
    chosen = answer["next"]["scenario"]
    after = load_plan(work)
    assert chosen in side_scenarios(after, b1)
    assert "pair 1's b side" in answer["reason"]
    if chosen not in side_scenarios(plan, b1):  # moved: a new variant with its range files and origin
        entry = next(v for v in after.variants if v["id"] == chosen)
        assert entry["variant_of"] == b1 and entry["origin"]["by"] == "rapt-plan next"
        assert entry["origin"]["reason"] == answer["reason"] and "moved" in answer["reason"]
        assert all((work / name).is_file() for name in entry["files"].values())
        assert chosen in json.loads((work / "plan.json").read_text())["run_order"]
    _valid(work / "plan.json")
    assert after.id == before  # the logs flown before still belong to the plan
    json.dumps({k: answer[k] for k in ("next", "reason", "pairs")})


def test_a_boundary_that_fell_through_gets_a_new_pair_from_the_noon_study(plan_dir, tmp_path, monkeypatch):
    import planner.conduct.new_pairs as new_pairs
    import planner.conduct.next_run as conductor
    from planner.conduct.day_record import DayRecord

    monkeypatch.setattr(conductor, "MOVE_BELOW", 0.0)  # no side is moved: the boundary can only be shown elsewhere
    work = plan_copy(plan_dir, tmp_path / "plan")
    plan = load_plan(work)
    before = plan.id
    # this small study's pairs are long (0.6-0.8 apart): none is offered as a plan's flown pair may not be
    assert not any(new_pairs.study_alternatives(plan).values())
    monkeypatch.setattr(new_pairs, "MAX_FLOWN_DISTANCE", 1.0)  # lifted, so the test has pairs to offer
    alternatives = new_pairs.study_alternatives(plan)
    for pair in plan.pairs:  # other stretches of the same boundary, away from the pair
        assert alternatives[str(pair["id"])]
        own = (plan.u(pair["scenarios"][0]) + plan.u(pair["scenarios"][1])) / 2
        for a, b in alternatives[str(pair["id"])]:
            assert np.linalg.norm((np.asarray(a) + np.asarray(b)) / 2 - own) >= new_pairs.MIN_APART
    day = afternoon(plan, [])
    (a1, b1), (a2, b2) = (p["scenarios"] for p in plan.pairs)
    runs = [_outcome(day, a2), _outcome(day, b2)]
    for side, other in ((a1, b1), (b1, a1)):  # every scenario of pair 1's sides showed the other side, 4 times
        for scen in side_scenarios(plan, side):
            runs += [RunOutcome(scen, np.asarray(day.predicted[other]), f"{scen}.mcap")] * 4
    record = DayRecord(plan.id, alternatives=alternatives)
    answer = decide(afternoon(plan, runs, record), 4)
    after = load_plan(work)
    added = [p for p in after.pairs if "origin" in p]
    assert len(added) == 1 and added[0]["origin"]["replaces"] == 1 and added[0]["id"] == 3
    assert answer["next"]["scenario"] in added[0]["scenarios"]
    assert "fell through" in answer["reason"] and "new pair 3" in answer["reason"]
    assert {p["id"]: p["status"] for p in answer["pairs"]} == {1: "lost", 2: "confirmed", 3: "open"}
    assert after.id == before
    _valid(work / "plan.json")
    assert all((work / name).is_file() for s in added[0]["scenarios"] for name in after.scenario(s)["files"].values())
    day = afternoon(after, runs, record)
    shown = runs + [_outcome(day, s) for s in added[0]["scenarios"]]
    done = decide(afternoon(after, shown, record), 0)
    assert done["reason"] == "done: no runs left; 2 of 2 boundaries confirmed"
