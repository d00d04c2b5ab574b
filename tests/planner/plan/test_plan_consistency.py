"""The committed plan agrees with itself, and the check names each kind of contradiction."""

from __future__ import annotations

import copy
import json
from pathlib import Path

from planner.common.plan_consistency import plan_contradictions

COMMITTED = Path(__file__).resolve().parents[3] / "field_plans" / "range2017" / "plan.json"


def _plan() -> dict:
    return json.loads(COMMITTED.read_text())


def test_the_committed_plan_agrees_with_itself():
    plan = _plan()
    assert plan["pairs"]
    assert plan_contradictions(plan) == []


def test_a_pair_written_with_modes_its_scenarios_do_not_predict_is_named():
    plan = _plan()
    pair = plan["pairs"][0]
    pair["modes"] = list(reversed(pair["modes"])) if pair["modes"][0] != pair["modes"][1] else ["TF", "TF"]
    problems = plan_contradictions(plan)
    assert len(problems) == 1 and problems[0].startswith("pair 1: written as")


def test_a_pair_whose_element_is_equal_on_both_sides_is_named():
    plan = _plan()
    pair = next(p for p in plan["pairs"] if p["level"] == 0)
    a, b = (next(s for s in plan["scenarios"] if s["id"] == sid) for sid in pair["scenarios"])
    element = pair["elements"][0]
    b["predicted"]["scores"][element] = a["predicted"]["scores"][element]
    assert any(f"its element {element}" in p for p in plan_contradictions(plan))


def test_a_variant_of_another_mode_or_side_and_a_wrong_p_straddle_are_named():
    plan = _plan()
    pair = next(p for p in plan["pairs"] if any(p.get("variants") or []))
    side = next(s for s, vid in enumerate(pair["variants"]) if vid)
    variant = next(v for v in plan["variants"] if v["id"] == pair["variants"][side])
    moved = copy.deepcopy(plan)
    v = next(v for v in moved["variants"] if v["id"] == variant["id"])
    v["predicted"]["mode"] = "TF" if variant["predicted"]["mode"] != "TF" else "SS"
    assert any("predicts" in p for p in plan_contradictions(moved))
    other = copy.deepcopy(plan)
    next(v for v in other["variants"] if v["id"] == variant["id"])["variant_of"] = "pair9a"
    assert any("is a variant of pair9a" in p for p in plan_contradictions(other))
    wrong = copy.deepcopy(plan)
    wrong_pair = next(p for p in wrong["pairs"] if p["id"] == pair["id"])
    wrong_pair["p_straddle"] = 0.999
    assert any("p_straddle" in p for p in plan_contradictions(wrong))
