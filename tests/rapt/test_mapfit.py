"""rapt.mapfit: a MAP fit that says which parameters its data identify, with honest standard errors."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.mapfit import IDENTIFIED_BELOW, Prior, fit_map

X = np.linspace(0.0, 10.0, 200)


def line_residuals(y: np.ndarray, sigma: float = 0.5):
    """y = a x + b fitted with a third parameter c the data cannot see."""

    def res(theta: np.ndarray) -> np.ndarray:
        a, b, _ = theta
        return (a * X + b - y) / sigma

    return res


PRIORS = [Prior("a", 1.0, 0.3, 0.0, 3.0), Prior("b", 0.0, 1.0), Prior("c", 0.0, 1.0, -5.0, 5.0)]


def test_identified_parameters_are_estimated_and_an_unseen_one_stays_at_its_prior():
    y = 1.3 * X + 0.4 + np.random.default_rng(0).normal(0, 0.5, X.size)
    fit = fit_map(line_residuals(y), PRIORS)
    assert fit.identified == {"a": True, "b": True, "c": False}
    assert fit.value["a"] == pytest.approx(1.3, abs=3 * fit.stderr["a"])
    assert fit.value["b"] == pytest.approx(0.4, abs=3 * fit.stderr["b"])
    assert fit.value["c"] == 0.0  # kept at the prior's centre for prediction
    assert fit.stderr["c"] == pytest.approx(1.0, rel=1e-3)  # its posterior is its prior
    assert fit.stderr["a"] < IDENTIFIED_BELOW * 0.3


@pytest.mark.parametrize("truth", [0.0, 0.4])
def test_a_prior_centred_on_its_bound_still_fits(truth):
    """A share whose file value is 0 in [0, 1] (a vehicle that keeps its speed through turns): the fit
    must still move it, and the other parameters, wherever the data say."""
    y = 1.3 * X + truth + np.random.default_rng(1).normal(0, 0.5, X.size)
    priors = [Prior("a", 1.0, 0.3, 0.0, 3.0), Prior("b", 0.0, 0.3, 0.0, 1.0), Prior("c", 0.0, 1.0, -5.0, 5.0)]
    fit = fit_map(line_residuals(y), priors)
    assert fit.identified["a"] and fit.value["a"] == pytest.approx(1.3, abs=3 * fit.stderr["a"])
    assert 0.0 <= fit.value["b"] <= 1.0
    if truth:  # moved off its bound to where the data put it
        assert fit.identified["b"] and fit.value["b"] == pytest.approx(truth, abs=3 * fit.stderr["b"])
    else:  # the data put it at its centre: within its error of 0, whether kept or fitted
        assert fit.value["b"] <= 3 * fit.stderr["b"]


def test_a_start_moves_where_the_search_begins_not_the_estimate():
    """A first guess from another measurement (a leg's power) far from the prior centre: the same MAP."""
    y = 1.3 * X + 0.4 + np.random.default_rng(2).normal(0, 0.5, X.size)
    plain = fit_map(line_residuals(y), PRIORS)
    started = fit_map(line_residuals(y), PRIORS, start={"a": 2.5, "b": -3.0})
    for n in ("a", "b"):
        assert started.value[n] == pytest.approx(plain.value[n], abs=1e-4)
        assert started.stderr[n] == pytest.approx(plain.stderr[n], rel=1e-3)
    assert started.identified == plain.identified


def test_of_two_confounded_parameters_the_one_the_data_explain_better_is_kept():
    # b and d enter as b + 0.98 d: neither alone is identified with both free; fixing the
    # one the data explain least (d, whose prior is narrow) leaves b identified
    y = 1.0 * X + 0.8 + np.random.default_rng(1).normal(0, 0.05, X.size)

    def res(theta):
        a, b, d = theta
        return (a * X + b + 0.98 * d - y) / 0.05

    fit = fit_map(res, [Prior("a", 1.0, 0.3), Prior("b", 0.0, 1.0), Prior("d", 0.0, 0.05)])
    assert fit.identified["b"] and not fit.identified["d"]
    assert fit.value["b"] == pytest.approx(0.8, abs=0.05)
    assert fit.value["d"] == 0.0


def test_block_bootstrap_widens_errors_that_are_correlated_within_groups():
    rng = np.random.default_rng(2)
    groups = np.repeat(np.arange(20), 10)
    shared = rng.normal(0, 1.0, 20)[groups]  # each group of 10 residuals moves together
    y = 1.3 * X + shared + rng.normal(0, 0.1, X.size)
    res = line_residuals(y, 0.1)
    plain = fit_map(res, PRIORS)
    robust = fit_map(res, PRIORS, groups=groups, bootstrap=60, seed=0)
    assert robust.stderr["b"] > 3 * plain.stderr["b"]
    assert robust.bootstrap == 60
    assert abs(robust.value["b"]) < 3 * robust.stderr["b"]  # the truth (0) is covered


def test_each_kind_of_residual_gets_its_own_noise_scale():
    rng = np.random.default_rng(3)
    precise = 2.0 * X + rng.normal(0, 0.01, X.size)
    noisy = 2.0 * X + rng.normal(0, 5.0, X.size)

    def res(theta):
        return np.concatenate([theta[0] * X - precise, theta[0] * X - noisy])

    kinds = np.repeat(["precise", "noisy"], X.size)
    fit = fit_map(res, [Prior("a", 1.0, 2.0)], kinds=kinds)
    assert fit.noise_scale["precise"] == pytest.approx(0.01, rel=0.3)
    assert fit.noise_scale["noisy"] == pytest.approx(5.0, rel=0.3)
    assert fit.stderr["a"] < 1e-3  # the precise kind is not drowned by the noisy one


def test_draws_vary_only_identified_parameters_and_respect_bounds():
    y = 1.3 * X + np.random.default_rng(4).normal(0, 0.5, X.size)
    fit = fit_map(line_residuals(y), PRIORS)
    d = fit.draws(50, seed=1)
    assert d.shape == (50, 3)
    assert np.all(d[:, 2] == 0.0) and np.std(d[:, 0]) > 0
    assert np.array_equal(d, fit.draws(50, seed=1))  # seeded


def test_a_prior_without_width_or_with_its_centre_outside_its_bounds_is_refused():
    with pytest.raises(ValueError, match="sd must be a positive"):
        Prior("a", 0.0, 0.0)
    with pytest.raises(ValueError, match="outside"):
        Prior("a", 5.0, 1.0, 0.0, 1.0)


@pytest.mark.parametrize("offset", [0.0, 10.0])
def test_departed_identifies_what_the_data_move_many_prior_widths_and_nothing_else(offset):
    """Data as precise as the prior (posterior s.d. 0.7 of the prior's: not identified by the prior's yardstick)
    that put the parameter ``offset`` prior widths from the file's value: moved far, it is identified and
    kept nearer the truth than the file's value; where the data agree with the file, nothing changes."""
    noise = 0.3 * np.sqrt(np.sum(X**2))  # the data know ``a`` as well as its prior (s.d. 0.3) does
    y = (1.0 + 0.3 * offset) * X + np.random.default_rng(3).normal(0, noise, X.size)
    priors = [Prior("a", 1.0, 0.3, 0.0, 10.0), Prior("b", 0.0, 1.0, -5.0, 5.0)]

    def res(theta: np.ndarray) -> np.ndarray:
        a, _ = theta
        return a * X - y  # in nominal units: the fit estimates the noise's scale

    kw = {"robust": False, "significant": 0.0}
    plain, departed = fit_map(res, priors, **kw), fit_map(res, priors, departed=True, **kw)
    assert not plain.identified["a"] and not plain.identified["b"]
    assert plain.stderr["a"] > IDENTIFIED_BELOW * 0.3
    if offset:
        assert departed.identified["a"] and not departed.identified["b"]
        truth = 1.0 + 0.3 * offset
        assert abs(departed.value["a"] - truth) < abs(plain.value["a"] - truth)
    else:
        assert departed.identified == plain.identified
