"""Systems built from other systems: reflected, padded with noise inputs, or stacked (section 3.6.3).

``Screened(Plates3D(), 4)`` is the 7-D screening system and :class:`Composite8D` the
8-input, 4-output system of eq. 3.12; distances stay exact because each wrapper maps a
point to its base's input isometrically (or drops columns the base ignores).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rapt.errors import InputError
from rapt.testfunctions.base import SyntheticSystem
from rapt.testfunctions.shapes import Custom2D, Plates2D, Rings2D

__all__ = ["Mirrored", "Screened", "Composite", "Composite8D"]


class Mirrored(SyntheticSystem):
    """A base system reflected (x -> 1 - x) along some input axes: same shapes, new places.

    Reflection is an isometry of the cube, so distances are the base's at the reflected
    point.  ``Mirrored(Plates2D(), (0, 1))`` is Plates2D rotated by 180 degrees.
    """

    def __init__(self, base: SyntheticSystem, axes: Sequence[int] = (0,), name: str | None = None):
        axes = tuple(int(a) for a in axes)
        if any(a < 0 or a >= base.dim for a in axes):
            raise InputError(f"axes must be input columns in 0..{base.dim - 1}, got {axes}")
        self.base = base
        self.axes = axes
        self.name = name or f"{base.name}-mirrored"
        self.dim = base.dim
        self.n_outputs = base.n_outputs
        self.output_types = tuple(base.output_types)
        self.n_classes = tuple(base.n_classes)
        self.active_dims = tuple(base.active_dims)

    def _reflect(self, X):
        Z = X.copy()
        Z[:, list(self.axes)] = 1.0 - Z[:, list(self.axes)]
        return Z

    def _evaluate(self, X):
        return self.base(self._reflect(X))

    def _distance(self, X):
        return self.base.boundary_distance(self._reflect(X))


class Screened(SyntheticSystem):
    """A base system with ``n_noise`` non-contributing inputs appended (section 3.6.3.1).

    The extra columns are ignored by the outputs, so ``active_dims`` stay the base's.
    ``Screened(Plates3D(), 4)`` is the 7-D screening system.
    """

    def __init__(self, base: SyntheticSystem, n_noise: int, name: str | None = None):
        if int(n_noise) != n_noise or n_noise < 0:
            raise InputError(f"n_noise must be a non-negative integer, got {n_noise!r}")
        self.base = base
        self.n_noise = int(n_noise)
        self.name = name or f"{base.name}+{self.n_noise}noise"
        self.dim = base.dim + self.n_noise
        self.n_outputs = base.n_outputs
        self.output_types = tuple(base.output_types)
        self.n_classes = tuple(base.n_classes)
        self.active_dims = tuple(base.active_dims)

    def _evaluate(self, X):
        return self.base(X[:, : self.base.dim])

    def _distance(self, X):
        return self.base.boundary_distance(X[:, : self.base.dim])


class Composite(SyntheticSystem):
    """Multiple-input multiple-output stack of independent systems (eq. 3.12).

    ``Composite([f1, f2, ...])`` feeds consecutive input columns to each part:
    ``f(x) = [f1(x[:d1]), f2(x[d1:d1+d2]), ...]``; its outputs are the parts' outputs in
    order and each output's ``active_dims`` are shifted accordingly.
    """

    def __init__(self, parts: Sequence[SyntheticSystem], name: str | None = None):
        parts = list(parts)
        if not parts:
            raise InputError("parts must contain at least one system")
        self.parts = parts
        self.name = name or "composite(" + ",".join(p.name for p in parts) + ")"
        self._offsets = np.cumsum([0] + [p.dim for p in parts]).tolist()
        self.dim = self._offsets[-1]
        self.n_outputs = sum(p.n_outputs for p in parts)
        self.output_types = tuple(t for p in parts for t in p.output_types)
        self.n_classes = tuple(c for p in parts for c in p.n_classes)
        self.active_dims = tuple(
            tuple(off + a for a in dims) for p, off in zip(parts, self._offsets) for dims in p.active_dims
        )

    def _blocks(self, X):
        return [X[:, lo:hi] for lo, hi in zip(self._offsets[:-1], self._offsets[1:])]

    def _evaluate(self, X):
        return np.hstack([p(B) for p, B in zip(self.parts, self._blocks(X))])

    def _distance(self, X):
        return np.hstack([p.boundary_distance(B) for p, B in zip(self.parts, self._blocks(X))])


class Composite8D(Composite):
    """The 8-input, 4-output composite system of eq. 3.12 (section 3.6.3.2).

    ``f(x) = [Plates2D(x1, x2), Custom2D(x3, x4), Plates2D-mirrored(x5, x6), Rings2D(x7, x8)]``;
    ``active_dims = ((0, 1), (2, 3), (4, 5), (6, 7))``.
    """

    def __init__(self) -> None:
        super().__init__([Plates2D(), Custom2D(), Mirrored(Plates2D(), (0, 1)), Rings2D()], name="composite8d")
