"""The interface every synthetic system under test implements.

Every system works on the unit cube ``[0, 1]^dim`` and exposes

* ``dim``, ``n_outputs``, ``output_types`` (``"categorical"`` or ``"continuous"`` per
  output), ``n_classes`` (class count per output, ``None`` when continuous), ``name``;
* ``system(X) -> Y`` for ``X`` of shape ``(n, dim)``; ``Y`` is ``(n, n_outputs)``
  float64, categorical labels are the floats ``0.0 .. C-1``;
* ``active_dims``: for each output, the input columns its boundary depends on;
* ``boundary_distance(X) -> (n, n_outputs)``: the exact Euclidean distance from each
  point to that output's true boundary, measured in the output's active subspace.
"""

from __future__ import annotations

import numpy as np

from rapt.errors import InputError

__all__ = ["SyntheticSystem", "CATEGORICAL", "CONTINUOUS"]

CATEGORICAL = "categorical"
CONTINUOUS = "continuous"


class SyntheticSystem:
    """Common interface of every synthetic system (see the module docstring)."""

    name: str = "system"
    dim: int
    n_outputs: int
    output_types: tuple[str, ...]
    n_classes: tuple[int | None, ...]
    active_dims: tuple[tuple[int, ...], ...]

    def _check(self, X) -> np.ndarray:
        X = np.asarray(X, dtype=float)
        if X.ndim != 2 or X.shape[1] != self.dim:
            raise InputError(
                f"X must be a 2-D array of shape (n, {self.dim}) for system '{self.name}'; got shape {X.shape}"
            )
        return X

    def __call__(self, X) -> np.ndarray:
        return self._evaluate(self._check(X))

    def boundary_distance(self, X) -> np.ndarray:
        return self._distance(self._check(X))

    def _evaluate(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _distance(self, X: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"<{type(self).__name__} '{self.name}' dim={self.dim} outputs={self.n_outputs}>"
