"""rapt.confirmation: the rule a side has shown by, and the run that most raises the boundaries confirmed."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from rapt.confirmation import (
    Option,
    Pair,
    Side,
    allocate,
    evidence,
    next_run,
    p_shown_within,
    pair_curve,
    side_status,
)


@pytest.mark.parametrize(
    ("shown", "missed", "status"),
    [
        (1, 0, "shown"),
        (0, 1, "against"),
        (1, 1, "open"),
        (2, 1, "open"),
        (3, 1, "shown"),
        (0, 2, "against"),
        (1, 2, "open"),
        (0, 0, "open"),
    ],  # fmt: skip
)
def test_one_run_that_shows_is_enough_and_after_a_miss_a_clear_majority(shown, missed, status):
    assert side_status(shown, missed) == status


def test_evidence_is_the_posterior_chance_the_side_shows_more_often_than_not():
    assert evidence(1, 0) == pytest.approx(0.75)  # Beta(2, 1): 1 - 0.5^2
    assert evidence(3, 1) == pytest.approx(1 - 6 / 32)  # Beta(4, 2) at 1/2: P(Bin(5, 1/2) >= 4)
    assert evidence(5, 5) == pytest.approx(0.5)


def test_a_sides_curve_starts_at_its_forecast_and_a_shown_side_is_certain():
    c = p_shown_within(Option(0.9), 6)
    assert c[0] == 0 and c[1] == pytest.approx(0.9)
    assert np.all(np.diff(c) >= -1e-12)  # more runs never lower the chance
    assert c[-1] > 0.95  # a miss can be made good: 3 of 4
    assert np.all(p_shown_within(Option(0.2, shown=1), 4) == 1.0)


def test_a_pair_needs_a_run_on_each_side():
    pair = Pair((Side((Option(0.9),)), Side((Option(0.8),))))
    c = pair_curve(pair, 4)
    assert c[0] == 0 and c[1] == 0
    assert c[2] == pytest.approx(0.72)


def test_the_day_split_is_the_best_of_every_split():
    curves = [
        pair_curve(Pair((Side((Option(p),)), Side((Option(q),)))), 7) for p, q in ((0.9, 0.6), (0.5, 0.95), (0.3, 0.3))
    ]
    value, split = allocate(curves, 7)
    best = max(sum(c[r] for c, r in zip(curves, rs)) for rs in itertools.product(range(8), repeat=3) if sum(rs) <= 7)
    assert value == pytest.approx(best)
    assert sum(split) <= 7 and sum(c[r] for c, r in zip(curves, split)) == pytest.approx(best)


def test_after_a_miss_a_likely_move_is_flown_rather_than_the_side_again():
    missed = Side((Option(0.9, missed=1), Option(0.85)))  # the scenario that missed, then a move
    pairs = [Pair((Side((Option(0.9, shown=1),)), missed))]
    choice = next_run(pairs, 3)
    assert (choice.pair, choice.side, choice.option) == (0, 1, 1)
    assert choice.expected > choice.now


def test_it_stops_when_every_pair_is_confirmed_or_no_run_is_worth_it():
    done = Pair((Side((Option(0.9, shown=1),)), Side((Option(0.9, shown=1),))))
    assert next_run([done, done], 5).pair is None
    hopeless = Pair((Side((Option(0.01, missed=3),)), Side((Option(0.9, shown=1),))))
    choice = next_run([done, hopeless], 2)
    assert choice.pair is None and choice.lost == [False, True]
    assert next_run([Pair((Side((Option(0.9),)), Side((Option(0.9),))))], 0).pair is None


def test_a_short_day_spends_its_runs_on_the_likeliest_pairs():
    sure = Pair((Side((Option(0.95),)), Side((Option(0.95),))))
    weak = Pair((Side((Option(0.3),)), Side((Option(0.3),))))
    choice = next_run([weak, sure], 2)
    assert choice.pair == 1
    assert choice.p_confirm[1] == pytest.approx(0.95**2) and choice.p_confirm[0] == 0.0


def test_a_lost_pair_is_confirmed_through_a_replacement_across_its_boundary():
    lost = Pair((Side((Option(0.05, missed=4),)), Side((Option(0.05, missed=4),))))
    assert next_run([lost], 3).lost == [True]
    fresh = Pair((Side((Option(0.9),)), Side((Option(0.85),))))
    with_new = Pair(lost.sides, replacements=(fresh,))
    choice = next_run([with_new], 3)
    assert choice.alternative == 1 and choice.pair == 0 and choice.lost == [False]
    assert choice.p_confirm[0] > 0.7
    done = Pair((Side((Option(0.9, shown=1),)), Side((Option(0.85, shown=1),))))
    shown = Pair(lost.sides, replacements=(done,))
    assert shown.confirmed and not shown.own_confirmed
