"""A pair side flown as its robust "M" variant stands for the side (a range flies the variants the plan made)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from planner.common.plans import load_plan
from planner.review.compare import _flown_as
from planner.review.runs import Observation

PLAN = Path(__file__).resolve().parents[3] / "field_plans" / "range2017" / "plan.json"


def _obs(sid: str, mode: str | None = "TS") -> Observation:
    return Observation(run=None, sid=sid, u=np.zeros(1), scores=np.zeros(2), mode=mode)  # type: ignore[arg-type]


def test_a_side_flown_itself_is_the_side():
    plan = load_plan(PLAN)
    assert _flown_as(plan, [_obs("pair4a"), _obs("pair4aM")], "pair4a") == "pair4a"


def test_a_side_flown_only_as_its_variant_is_judged_by_the_variant():
    plan = load_plan(PLAN)
    assert {v["variant_of"]: v["id"] for v in plan.variants}["pair4a"] == "pair4aM"
    assert _flown_as(plan, [_obs("pair4aM"), _obs("pair4b")], "pair4a") == "pair4aM"
    assert _flown_as(plan, [_obs("pair4aM"), _obs("pair4b")], "pair4b") == "pair4b"


def test_a_run_without_an_observed_mode_does_not_stand_for_the_side():
    plan = load_plan(PLAN)
    assert _flown_as(plan, [_obs("pair4aM", mode=None)], "pair4a") == "pair4a"
    assert _flown_as(plan, [], "pair1a") == "pair1a"
