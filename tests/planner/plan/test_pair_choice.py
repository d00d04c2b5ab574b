"""Pairs chosen by the chance that both flown sides show their outcomes, not by their length alone."""

from __future__ import annotations

import numpy as np
import pytest

from planner.plan.dithering import Outcome
from planner.plan.pair_choice import MAX_FLOWN_DISTANCE, Candidate, rank_candidates


def _cand(level, elements, p_a, p_b, distance=0.03, variants=(None, None), d=4):
    U = np.full((2, d), 0.5)
    U[1, 0] += distance
    o = Outcome(1, (0, 1), (0.0, 1.0))
    c = Candidate({"level": level, "elements": list(elements), "distance": distance}, U, [o, o])
    c.stats = [{"p_predicted": p_a}, {"p_predicted": p_b}]
    c.variants = list(variants)
    return c


def _variant(p, u):
    return {"found": True, "p_predicted": p, "u": list(u)}


def test_the_pairs_most_likely_to_show_are_kept_whatever_their_length_in_the_candidates_order():
    short_fragile = _cand(0, ["mission_success"], 0.55, 0.6, distance=0.02)
    longer_robust = _cand(1, ["waypoints"], 0.95, 0.93, distance=0.045)
    robust_too = _cand(2, ["waypoint.0"], 0.9, 0.9, distance=0.04)
    ranked = rank_candidates([short_fragile, longer_robust, robust_too], 2)
    assert ranked == [longer_robust, robust_too]
    assert ranked[0].p_straddle == pytest.approx(0.95 * 0.93)


def test_one_pair_per_sub_boundary_and_no_more_than_asked():
    a = _cand(0, ["mission_success"], 0.9, 0.9)
    same_boundary = _cand(0, ["mission_success"], 0.99, 0.99)
    b = _cand(2, ["waypoint.0"], 0.8, 0.8)
    c = _cand(1, ["waypoints"], 0.7, 0.7)
    ranked = rank_candidates([a, same_boundary, b, c], 2)
    assert ranked == [same_boundary, b]
    assert rank_candidates([c, b, a], 2) == [b, a]  # kept by P, listed as offered


def test_undithered_candidates_keep_their_order():
    a, b = _cand(0, ["x"], None, None), _cand(1, ["y"], None, None)
    assert rank_candidates([a, b], 2) == [a, b]


def test_a_fragile_side_flies_its_variant_and_p_straddle_is_the_flown_sides_product():
    c = _cand(0, ["mission_success"], 0.5, 0.95)
    c.variants = [_variant(0.92, c.U[0] - [0.05, 0, 0, 0]), None]
    c.choose_flown(target=0.9)
    assert c.flies_variant == [True, False]
    assert c.p_straddle == pytest.approx(0.92 * 0.95)
    assert c.flown_distance == pytest.approx(0.08)


def test_a_variant_that_takes_the_sides_too_far_apart_is_not_flown():
    c = _cand(0, ["mission_success"], 0.5, 0.95)
    c.variants = [_variant(0.99, c.U[0] - [MAX_FLOWN_DISTANCE, 0, 0, 0]), None]
    c.choose_flown(target=0.9)
    assert c.flies_variant == [False, False] and c.p_straddle == pytest.approx(0.5 * 0.95)


def test_a_side_already_at_the_target_flies_as_written():
    c = _cand(0, ["mission_success"], 0.91, 0.5)
    c.variants = [_variant(0.99, c.U[0] - [0.02, 0, 0, 0]), _variant(0.93, c.U[1] + [0.02, 0, 0, 0])]
    c.choose_flown(target=0.9)
    assert c.flies_variant == [False, True]


def test_a_side_with_only_a_variant_under_the_target_flies_it_where_it_holds_more_often():
    c = _cand(0, ["mission_success"], 0.4, 0.95)
    closest = _variant(0.86, c.U[0] - [0.05, 0, 0, 0])
    c.variants = [{"found": False, "reason": "no variant found", "closest": closest}, None]
    c.choose_flown(target=0.9)
    assert c.flies_variant == [True, False] and c.p_straddle == pytest.approx(0.86 * 0.95)
    worse = _cand(0, ["mission_success"], 0.7, 0.95)
    worse.variants = [{"found": False, "closest": _variant(0.6, worse.U[0] - [0.05, 0, 0, 0])}, None]
    worse.choose_flown(target=0.9)
    assert worse.flies_variant == [False, False]
