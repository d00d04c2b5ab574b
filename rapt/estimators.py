"""scikit-learn estimators around the boundary-identification functions.

The functions (:func:`rapt.performance_modes`, :func:`rapt.boundary_pairs`) are the
contract; these wrappers give them scikit-learn's shape — parameters stored untouched in
``__init__``, validation in ``fit``, results in trailing-underscore attributes — so they
work with ``clone``, ``get_params`` and pipelines, and pass ``check_estimator``.
"""

from __future__ import annotations

from numbers import Integral, Real

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils._param_validation import Interval
from sklearn.utils.validation import validate_data

from rapt.boundaries import boundary_pairs
from rapt.modes import performance_modes

__all__ = ["PerformanceModes", "BoundaryPairFinder"]


class PerformanceModes(ClusterMixin, BaseEstimator):
    """Performance modes of score rows: ``fit(Y).labels_``.

    Parameters are those of :func:`rapt.performance_modes`; ``output_types=None`` infers
    each column's kind.
    """

    _parameter_constraints: dict = {
        "output_types": [list, tuple, None],
        "bandwidth": [Interval(Real, 0, None, closed="neither")],
        "bin_seeding": ["boolean"],
    }

    def __init__(self, *, output_types=None, bandwidth=0.2, bin_seeding=True):
        self.output_types = output_types
        self.bandwidth = bandwidth
        self.bin_seeding = bin_seeding

    def fit(self, X, y=None):
        """Label each row of scores ``X`` with its mode; returns ``self``."""
        self._validate_params()
        X = validate_data(self, X, dtype=np.float64)
        self.labels_ = performance_modes(X, self.output_types, bandwidth=self.bandwidth, bin_seeding=self.bin_seeding)
        self.n_modes_ = int(self.labels_.max()) + 1
        return self


class BoundaryPairFinder(BaseEstimator):
    """Boundary pairs of states ``X`` with scores ``y``: ``fit(X, y).pairs_``.

    Parameters are those of :func:`rapt.boundary_pairs`.
    """

    _parameter_constraints: dict = {
        "output_types": [list, tuple, None],
        "bandwidth": [Interval(Real, 0, None, closed="neither")],
        "d_eps": [Interval(Real, 0, None, closed="neither"), None],
        "quantile": [Interval(Real, 0, 1, closed="right"), None],
        "cluster_eps": [Interval(Real, 0, None, closed="neither"), None],
        "min_samples": [Interval(Integral, 1, None, closed="left")],
    }

    def __init__(
        self, *, output_types=None, bandwidth=0.2, d_eps=None, quantile=None, cluster_eps=None, min_samples=20
    ):
        self.output_types = output_types
        self.bandwidth = bandwidth
        self.d_eps = d_eps
        self.quantile = quantile
        self.cluster_eps = cluster_eps
        self.min_samples = min_samples

    def fit(self, X, y):
        """Find, threshold and rank the boundary pairs; returns ``self``."""
        self._validate_params()
        X, y = validate_data(self, X, y, dtype=np.float64, multi_output=True, y_numeric=True)
        self.pairs_ = boundary_pairs(
            X,
            y,
            output_types=self.output_types,
            bandwidth=self.bandwidth,
            d_eps=self.d_eps,
            quantile=self.quantile,
            cluster_eps=self.cluster_eps,
            min_samples=self.min_samples,
        )
        self.labels_ = self.pairs_.labels
        return self
