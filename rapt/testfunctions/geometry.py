"""Exact (signed) distances to the shapes the synthetic systems are built from.

A synthetic system's boundary distance must be exact for the search-quality metrics to
mean anything, so every shape here comes with its closed-form Euclidean (signed)
distance, vectorised over the rows of ``P``.  Signed distances are negative inside.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = [
    "segment_distance",
    "convex_polygon_sdf",
    "norm",
    "sphere_sdf",
    "annulus_sdf",
    "box_sdf",
    "torus_sdf",
    "cylinder_sdf",
]


def segment_distance(P: np.ndarray, a: Sequence[float], b: Sequence[float]) -> np.ndarray:
    """Euclidean distance from each row of ``P`` (n, k) to the segment ``[a, b]``."""
    start = np.asarray(a, dtype=float)
    ab = np.asarray(b, dtype=float) - start
    ap = P - start
    t = np.clip(ap @ ab / (ab @ ab), 0.0, 1.0)
    diff = ap - t[:, None] * ab
    return np.sqrt(np.einsum("ij,ij->i", diff, diff))


def convex_polygon_sdf(P: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Exact signed distance from 2-D points ``P`` (n, 2) to a convex polygon.

    ``vertices`` (m, 2) must be in counter-clockwise order.  The magnitude is the
    minimum distance to the edges; the sign is negative inside (all edge cross products
    non-negative) and positive outside.
    """
    V = np.asarray(vertices, dtype=float)
    dist = np.full(P.shape[0], np.inf)
    inside = np.ones(P.shape[0], dtype=bool)
    for k in range(len(V)):
        a, b = V[k], V[(k + 1) % len(V)]
        dist = np.minimum(dist, segment_distance(P, a, b))
        e = b - a
        cross = e[0] * (P[:, 1] - a[1]) - e[1] * (P[:, 0] - a[0])
        inside &= cross >= 0.0
    return np.where(inside, -dist, dist)


def norm(D: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", D, D))


def sphere_sdf(P, center, radius):
    return norm(P - np.asarray(center, dtype=float)) - radius


def annulus_sdf(P, center, r_in, r_out):
    mid, half = 0.5 * (r_in + r_out), 0.5 * (r_out - r_in)
    return np.abs(norm(P - np.asarray(center, dtype=float)) - mid) - half


def box_sdf(P, center, half):
    """Exact signed distance to an axis-aligned box (any dimension)."""
    q = np.abs(P - np.asarray(center, dtype=float)) - np.asarray(half, dtype=float)
    outside = norm(np.maximum(q, 0.0))
    inside = np.minimum(q.max(axis=1), 0.0)
    return outside + inside


def torus_sdf(P, center, R, r):
    """Exact signed distance to a torus with axis along x3 (major R, minor r)."""
    D = P - np.asarray(center, dtype=float)
    rho = np.hypot(D[:, 0], D[:, 1]) - R
    return np.hypot(rho, D[:, 2]) - r


def cylinder_sdf(P, center, radius, half_height):
    """Exact signed distance to a capped cylinder with axis along x3."""
    D = P - np.asarray(center, dtype=float)
    dr = np.hypot(D[:, 0], D[:, 1]) - radius
    dz = np.abs(D[:, 2]) - half_height
    outside = np.hypot(np.maximum(dr, 0.0), np.maximum(dz, 0.0))
    return outside + np.minimum(np.maximum(dr, dz), 0.0)
