"""The afternoon's decision (planner.conduct.next_run.decide) on a small plan, from runs given as outcomes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from planner.common.plans import load_plan
from planner.conduct.next_run import afternoon, decide
from planner.review.confirmations import RunOutcome, side_scenarios
from tests.support.small_plan import plan_copy


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
    assert after.id == before  # the logs flown before still belong to the plan
    json.dumps({k: answer[k] for k in ("next", "reason", "pairs")})
