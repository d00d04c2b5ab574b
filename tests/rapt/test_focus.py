"""The focused pair search: sharp pairs round a third combination, replacement, determinism, errors."""

import numpy as np
import pytest

from rapt.errors import InputError
from rapt.focus import OTHER, SIDE_A, SIDE_B, PairFocus, sharpen_pairs

D = 15  # as many coordinates as the 2017 range mission


def blocked(U, owner=None):
    """A on x0 < 0.5, B above; a third combination blocks the straight segment at x0 = 0.5."""
    labels = np.where(U[:, 0] < 0.5, SIDE_A, SIDE_B)
    block = (np.abs(U[:, 0] - 0.5) < 0.1) & (np.abs(U[:, 1] - 0.5) < 0.1)
    return np.where(block, OTHER, labels)


def pair(x_a=0.3, x_b=0.7, seed=0):
    rng = np.random.default_rng(seed)
    a = 0.4 + 0.2 * rng.random(D)
    a[1] = 0.5
    b = a.copy()
    a[0], b[0] = x_a, x_b
    return a, b


def test_a_pair_whose_segment_crosses_a_third_combination_comes_back_sharp():
    a, b = pair()
    assert blocked(((a + b) / 2)[None, :])[0] == OTHER  # bisection would stop at its first midpoint
    [out] = sharpen_pairs(blocked, [(a, b)], 1, runs=192, min_distance=0.02, max_distance=0.05, seed=3)
    assert out.sharp and 0.02 <= out.distance <= 0.05 < out.start_distance
    assert blocked(np.vstack([out.a, out.b])).tolist() == [SIDE_A, SIDE_B]  # still the same sub-boundary
    assert out.runs <= 192


def test_an_unrefinable_candidate_is_replaced_by_the_next():
    def gap(U, owner):  # candidate 0: A and B 0.3 apart with nothing but a third combination between
        x = U[:, 0]
        wide = np.where(x < 0.35, SIDE_A, np.where(x > 0.65, SIDE_B, OTHER))
        return np.where(owner == 0, wide, blocked(U))

    outcomes = sharpen_pairs(gap, [pair(0.2, 0.8), pair()], 1, runs=192, min_distance=0.02, max_distance=0.05, seed=3)
    assert [o.candidate for o in outcomes] == [0, 1]
    assert not outcomes[0].sharp and outcomes[0].distance >= 0.3  # no pair closer than the gap exists
    assert outcomes[1].sharp and outcomes[1].distance <= 0.05


def test_known_samples_in_the_ball_seed_the_search_and_the_same_seed_gives_the_same_pair():
    a, b = pair()
    rng = np.random.default_rng(0)
    X = np.clip((a + b) / 2 + 0.01 * rng.standard_normal((400, D)), 0, 1)
    X[:, 0], X[:, 1] = rng.uniform(0.3, 0.7, 400), 0.3  # beside the block
    X[0] = 0.0  # far outside the ball: left out
    f = PairFocus(a, b, runs=64, min_distance=0.02, X_known=X, labels_known=blocked(X))
    assert len(f.data()[0]) == 2 + 399  # the study's runs inside the ball came in, free
    assert f.distance < np.linalg.norm(a - b)  # and already shortened the pair
    first = sharpen_pairs(blocked, [(a, b)], 1, runs=96, min_distance=0.02, max_distance=0.05, seed=5)[0]
    again = sharpen_pairs(blocked, [(a, b)], 1, runs=96, min_distance=0.02, max_distance=0.05, seed=5)[0]
    np.testing.assert_array_equal(first.a, again.a)
    np.testing.assert_array_equal(first.b, again.b)


def test_the_floor_is_kept_and_bad_input_is_one_line():
    a, b = pair()
    f = PairFocus(a, b, runs=400, min_distance=0.1)
    while not f.done:
        U = f.ask()
        f.tell(U, blocked(U))
    assert 0.1 <= f.distance < 0.2 and f.spent < 400  # stops short of the floor rather than under it
    with pytest.raises(InputError, match=r"^a, b: expected two unit-cube rows"):
        PairFocus(a, b[:3], runs=10, min_distance=0.02)
    with pytest.raises(InputError, match=r"^runs: "):
        PairFocus(a, b, runs=-1, min_distance=0.02)
    with pytest.raises(InputError, match=r"^max_distance: "):
        sharpen_pairs(blocked, [(a, b)], 1, runs=16, min_distance=0.05, max_distance=0.05)
