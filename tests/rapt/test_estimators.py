"""The scikit-learn wrappers pass scikit-learn's own estimator checks and agree with the plain functions."""

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.utils.estimator_checks import parametrize_with_checks

import rapt
from rapt.estimators import BoundaryPairFinder, PerformanceModes
from rapt.testfunctions.shapes import Plates2D


@parametrize_with_checks([PerformanceModes(), BoundaryPairFinder()])
def test_scikit_learn_contract(estimator, check):
    check(estimator)


def test_estimators_match_the_functions():
    X = np.random.default_rng(0).random((800, 2))
    Y = Plates2D()(X)
    modes = PerformanceModes().fit(Y)
    assert np.array_equal(modes.labels_, rapt.performance_modes(Y))
    finder = clone(BoundaryPairFinder(quantile=0.2)).fit(X, Y)
    direct = rapt.boundary_pairs(X, Y, quantile=0.2)
    assert np.array_equal(finder.pairs_.i, direct.i) and np.array_equal(finder.pairs_.j, direct.j)
    with pytest.raises(ValueError, match="quantile"):
        BoundaryPairFinder(quantile=2.0).fit(X, Y)
