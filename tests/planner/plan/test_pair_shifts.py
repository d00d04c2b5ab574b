"""Pairs moved as a whole: both sides shifted by one move, so the pair keeps its length and its boundary."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.plan.pair_choice import Dithering, dither_candidates, write_candidates
from planner.plan.pair_shifts import SHIFT_SIGMAS, shifted_pairs, with_shifted_pairs
from tests.planner.plan.test_pair_choice import _cand

ROOT = Path(__file__).resolve().parents[3]


SIGMA = np.array([0.02, 0.01, 0.04, 0.005])


def test_a_pair_with_one_fragile_side_moves_whole_away_from_it_and_keeps_its_length():
    c = _cand(0, ["mission_success"], 0.5, 0.95)  # side a (at x = 0.5) flips; side b (x = 0.53) holds
    moved = shifted_pairs([c], SIGMA, target=0.9, limit=5)
    assert moved and all(m["shift_of"] == 0 and m["level"] == 0 for m in moved)
    for m in moved:
        U = np.asarray(m["u_override"])
        assert np.linalg.norm(U[1] - U[0]) == pytest.approx(0.03)  # the pair's length and direction stay
        shift = U[0] - c.U[0]
        assert np.allclose(U[1] - c.U[1], shift)
        assert np.linalg.norm(shift) == pytest.approx(m["shifted"]["by"])
    normal = [m for m in moved if m["shifted"]["along"] == "normal"]
    # away from the fragile side a: toward -x, by 1 and 2 sigmas of the noise along x
    assert [np.asarray(m["u_override"])[0, 0] - 0.5 for m in normal] == pytest.approx(
        [-k * SIGMA[0] for k in SHIFT_SIGMAS]
    )
    along = [m for m in moved if m["shifted"]["along"] == "boundary"]
    # along the boundary on its two noisiest coordinates (2 and 1), both ways, never across it
    assert {int(np.flatnonzero(np.asarray(m["u_override"])[0] - c.U[0])[0]) for m in along} == {1, 2}
    assert all(np.asarray(m["u_override"])[0, 0] == pytest.approx(0.5) for m in along)


def test_robust_pairs_and_shifts_that_leave_the_cube_are_not_moved_and_the_likeliest_go_first():
    robust = _cand(0, ["x"], 0.95, 0.95)
    assert shifted_pairs([robust], SIGMA, target=0.9, limit=5) == []
    both = _cand(1, ["y"], 0.5, 0.6)  # both sides fragile: no side to move toward, only along the boundary
    assert {m["shifted"]["along"] for m in shifted_pairs([both], SIGMA, 0.9, 5)} == {"boundary"}
    edge = _cand(2, ["z"], 0.5, 0.95)
    edge.U[:, 2] = 0.99  # the noisiest coordinate at the cube's edge: only the shifts that stay inside
    assert all(np.all(np.asarray(m["u_override"]) <= 1.0) for m in shifted_pairs([edge], SIGMA, 0.9, 5))
    unlikely = _cand(3, ["w"], 0.3, 0.3)
    firsts = {m["shift_of"] for m in shifted_pairs([unlikely, both], SIGMA, 0.9, limit=1)}
    assert firsts == {1}  # the limit takes the likelier pair (0.5 x 0.6) first


def test_only_the_likeliest_pair_of_a_sub_boundary_no_candidate_holds_on_is_moved():
    fragile = _cand(0, ["x"], 0.5, 0.95)
    holds = _cand(0, ["x"], 0.92, 0.95)  # the same sub-boundary already shows: the plan keeps this one
    assert shifted_pairs([fragile, holds], SIGMA, 0.9, 5) == []
    likelier = _cand(1, ["y"], 0.7, 0.8)
    less = _cand(1, ["y"], 0.5, 0.6)
    other = _cand(2, ["y"], 0.5, 0.6)  # another level: another sub-boundary
    assert {m["shift_of"] for m in shifted_pairs([less, likelier, other], SIGMA, 0.9, 5)} == {1, 2}
    assert {m["shift_of"] for m in shifted_pairs([less, likelier, other], SIGMA, 0.9, 1)} == {1}


@pytest.mark.slow  # dithers and confirms shifts of a range2017 pair: about 20 s on 2 cores
def test_a_fragile_pair_of_the_range_mission_is_moved_screened_and_confirmed_beside_its_origin():
    mission = sim.uuv.load_mission(ROOT / "examples" / "range2017.toml")
    plan = json.loads((ROOT / "field_plans" / "range2017" / "plan.json").read_text())
    pair = plan["pairs"][0]  # a root-mode pair whose side a holds 61 % as written: fragile
    u = {sc["id"]: sc["u"] for sc in plan["scenarios"]}
    U = np.asarray([u[sid] for sid in pair["scenarios"]], dtype=float)
    sigma = np.asarray(plan["study"]["dithering"]["sigma_u"], dtype=float)
    how = Dithering(400, sigma, np.ones(mission.dim), 0.9, 5)
    levels = [[0, 1]]
    origin = write_candidates(mission, levels, [{"level": 0}], lambda p: U)
    dither_candidates(mission, origin, how, variants=False)  # as written: no variant to fly
    assert len(origin) == 1 and min(origin[0].stats[s]["p_predicted"] for s in (0, 1)) < 0.9
    out, runs = with_shifted_pairs(mission, levels, origin, how, pairs=1, budget=10**6)
    assert out[0] is origin[0]  # the origin keeps its place; its moves follow it
    moved = out[1:]
    proposed = shifted_pairs(origin, sigma, 0.9, 2)
    assert runs >= 2 * len(proposed) + 2 * 40 * len(proposed)  # each written once and screened
    assert 1 <= len(moved) <= 2, "2 sigmas along this boundary it is less sensitive: a shift straddles more often"
    for m in moved:
        assert m.pair["shift_of"] == 0 and m.pair["shifted"]["along"] in ("normal", "boundary")
        shift = m.U - origin[0].U  # both sides by one move: they differ by the range's resolution only
        assert np.linalg.norm(shift[0] - shift[1]) < 0.1 * m.pair["shifted"]["by"]
        assert m.pair["modes"][0] != m.pair["modes"][1] and m.pair["elements"] == ["mission_success"]
        assert [len(m.dithers[s][1]) for s in (0, 1)] == [200, 200]  # confirmed in full, not by the screen
        assert m.p_straddle is not None
    # a budget the screen alone spends: no round of confirmation starts, the origin stands alone
    alone, screened = with_shifted_pairs(mission, levels, origin, how, pairs=1, budget=1)
    assert alone == origin and 0 < screened < runs


def test_the_report_says_how_a_pair_was_moved():
    from planner.plan.report import _summary_table

    plan = json.loads((ROOT / "field_plans" / "range2017" / "plan.json").read_text())
    plan["pairs"][1]["shifted"] = {"along": "boundary", "sigmas": 2.0, "by": 0.0984}
    assert "moved as a whole 2 noise sigmas along its boundary (0.098 in the unit cube)" in _summary_table(plan)
    del plan["pairs"][1]["shifted"]
    assert "moved as a whole" not in _summary_table(plan)
