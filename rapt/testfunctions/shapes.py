"""Systems whose boundaries are the outlines of known shapes (section 3.6.1 of the dissertation).

Custom2D, Plates2D and Plates3D are the dissertation's stand-ins; Rings2D is a third
categorical 2-D system for the composite.  Their boundaries are unions of circles,
segments, polygons and solids whose exact distances :mod:`rapt.testfunctions.geometry`
gives.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from rapt.errors import InputError
from rapt.testfunctions.base import CATEGORICAL, CONTINUOUS, SyntheticSystem
from rapt.testfunctions.geometry import (
    annulus_sdf,
    box_sdf,
    convex_polygon_sdf,
    cylinder_sdf,
    norm,
    segment_distance,
    sphere_sdf,
    torus_sdf,
)

__all__ = ["Plates2D", "Rings2D", "Custom2D", "Plates3D"]


class _Plates(SyntheticSystem):
    """Background (class 0) plus disjoint solids labelled 1..k; boundary = their outlines."""

    _shapes: list[Callable[[np.ndarray], np.ndarray]]

    def _setup(self, dim: int, name: str) -> None:
        self.dim = dim
        self.name = name
        self.n_outputs = 1
        self.output_types = (CATEGORICAL,)
        self.n_classes = (len(self._shapes) + 1,)
        self.active_dims = (tuple(range(dim)),)

    def signed_distances(self, X) -> np.ndarray:
        """(n, n_shapes) signed distance to each solid (negative inside)."""
        X = self._check(X)
        return np.column_stack([sdf(X) for sdf in self._shapes])

    def _evaluate(self, X):
        label = np.zeros(X.shape[0])
        for k, sdf in enumerate(self._shapes, start=1):
            label[sdf(X) < 0.0] = k
        return label[:, None]

    def _distance(self, X):
        d = np.full(X.shape[0], np.inf)
        for sdf in self._shapes:
            d = np.minimum(d, np.abs(sdf(X)))
        return d[:, None]


# ---------------------------------------------------------------------- 2-D systems
class Plates2D(_Plates):
    """Plates2D (section 3.6.1): 5 performance modes on the unit square.

    Class 0 is the background; 1 is a disk, 2 an axis-aligned rectangle, 3 a triangle and
    4 an annulus (whose hole is background).  The plates are disjoint and lie inside the
    square, so the boundary is the union of their outlines (total length ~3.0).
    """

    DISK = ((0.22, 0.75), 0.09)
    RECT = ((0.68, 0.75), (0.11, 0.07))
    TRIANGLE = np.array([[0.14, 0.15], [0.36, 0.15], [0.25, 0.36]])
    ANNULUS = ((0.70, 0.30), 0.05, 0.11)

    def __init__(self) -> None:
        (dc, dr), (rc, rh), tri, (ac, ai, ao) = self.DISK, self.RECT, self.TRIANGLE, self.ANNULUS
        self._shapes = [
            lambda X: sphere_sdf(X, dc, dr),
            lambda X: box_sdf(X, rc, rh),
            lambda X: convex_polygon_sdf(X, tri),
            lambda X: annulus_sdf(X, ac, ai, ao),
        ]
        self._setup(2, "plates2d")


class Rings2D(SyntheticSystem):
    """Concentric-rings categorical system: 3 modes split by two circles.

    Class 2 inside radius 0.12, class 1 between radii 0.12 and 0.30, class 0 outside;
    both circles are centred at (0.55, 0.45) and lie inside the square (length ~2.6).
    """

    CENTER = (0.55, 0.45)
    RADII = (0.12, 0.30)

    def __init__(self) -> None:
        self.name = "rings2d"
        self.dim = 2
        self.n_outputs = 1
        self.output_types = (CATEGORICAL,)
        self.n_classes = (3,)
        self.active_dims = ((0, 1),)

    def _rho(self, X):
        return norm(X - np.asarray(self.CENTER))

    def _evaluate(self, X):
        rho = self._rho(X)
        r1, r2 = self.RADII
        return np.where(rho < r1, 2.0, np.where(rho < r2, 1.0, 0.0))[:, None]

    def _distance(self, X):
        rho = self._rho(X)
        r1, r2 = self.RADII
        return np.minimum(np.abs(rho - r1), np.abs(rho - r2))[:, None]


class Custom2D(SyntheticSystem):
    """Custom2D (section 3.6.1): one continuous output with peaks, valleys, plateaus, cliffs.

    The gentle landscape is a tilted plane, two Gaussian peaks and one Gaussian valley
    (gradient magnitude below ~5).  Two cliffs, each a tanh step of height ~1 over a
    width of ~``2 * width`` (max slope ~``0.5 / width`` = 250), form the true
    boundaries, i.e. the local maxima of the first derivative:

    * a circle (centre (0.30, 0.62), radius 0.20) enclosing a flat plateau at 1.5;
    * a straight cliff from (0.50, 0) to (1, 0.75) that raises the lower-right region by 1.

    Total boundary length ~2.16.
    """

    CIRCLE = ((0.30, 0.62), 0.20)
    SEGMENT = ((0.50, 0.0), (1.0, 0.75))
    PLATEAU = 1.5
    PEAKS = (((0.62, 0.78), 0.12, 0.6), ((0.85, 0.25), 0.10, 0.4), ((0.20, 0.20), 0.10, -0.5))

    def __init__(self, width: float = 0.002) -> None:
        if not width > 0:
            raise InputError(f"width must be > 0, got {width!r}")
        self.width = float(width)
        self.name = "custom2d"
        self.dim = 2
        self.n_outputs = 1
        self.output_types = (CONTINUOUS,)
        self.n_classes = (None,)
        self.active_dims = ((0, 1),)
        a, b = (np.asarray(p, dtype=float) for p in self.SEGMENT)
        e = b - a
        self._a = a
        self._normal = np.array([e[1], -e[0]]) / np.hypot(*e)  # points to the lower right

    def gentle(self, X) -> np.ndarray:
        """The smooth part (plane + Gaussian peaks/valley), without the cliffs."""
        X = self._check(X)
        g = 0.25 * X[:, 0] + 0.15 * X[:, 1]
        for c, s, amp in self.PEAKS:
            D = X - np.asarray(c)
            g = g + amp * np.exp(-np.einsum("ij,ij->i", D, D) / (2.0 * s * s))
        return g

    def _evaluate(self, X):
        (c, r), w = self.CIRCLE, self.width
        line_sd = (X - self._a) @ self._normal
        outside = self.gentle(X) + 0.5 * (1.0 + np.tanh(line_sd / w))
        s = 0.5 * (1.0 + np.tanh((r - norm(X - np.asarray(c))) / w))
        return (s * self.PLATEAU + (1.0 - s) * outside)[:, None]

    def _distance(self, X):
        c, r = self.CIRCLE
        d_circle = np.abs(norm(X - np.asarray(c)) - r)
        d_line = segment_distance(X, *self.SEGMENT)
        return np.minimum(d_circle, d_line)[:, None]


# ---------------------------------------------------------------------- 3-D systems
class Plates3D(_Plates):
    """Plates3D (section 3.6.1): 5 performance modes in the unit cube.

    Class 0 is the background; 1 a sphere, 2 an axis-aligned box, 3 a torus (axis x3)
    and 4 a capped cylinder (axis x3).  All four have exact signed distances, are
    disjoint and lie inside the cube (total surface area ~1.3).
    """

    SPHERE = ((0.25, 0.25, 0.25), 0.14)
    BOX = ((0.72, 0.26, 0.72), (0.14, 0.11, 0.12))
    TORUS = ((0.70, 0.70, 0.28), 0.14, 0.05)
    CYLINDER = ((0.27, 0.70, 0.68), 0.12, 0.14)

    def __init__(self) -> None:
        (sc, sr), (bc, bh) = self.SPHERE, self.BOX
        (tc, tR, tr), (cc, cr, ch) = self.TORUS, self.CYLINDER
        self._shapes = [
            lambda X: sphere_sdf(X, sc, sr),
            lambda X: box_sdf(X, bc, bh),
            lambda X: torus_sdf(X, tc, tR, tr),
            lambda X: cylinder_sdf(X, cc, cr, ch),
        ]
        self._setup(3, "plates3d")
