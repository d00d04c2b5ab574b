"""Vectorised 2-D geometry for many scenarios at once: rectangles and triangles.

Every function takes points of shape (N, 2) (or (N,) x and y arrays) and shapes with a
leading scenario axis, (N, K, ...), because each scenario places its own no-go areas and
obstacles.  Signed distances are negative inside, so "closest approach" and "how deep
inside" are one number.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "rect_signed_distance",
    "rect_closest_point",
    "triangle_vertices",
    "polygon_signed_distance",
    "inside_rect",
    "polygon_edges",
]


def rect_closest_point(x: np.ndarray, y: np.ndarray, rects: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point of each axis-aligned rectangle (N, K, 4: xmin, xmax, ymin, ymax) to (x, y)."""
    cx = np.clip(x[:, None], rects[..., 0], rects[..., 1])
    cy = np.clip(y[:, None], rects[..., 2], rects[..., 3])
    return cx, cy


def rect_signed_distance(x: np.ndarray, y: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """(N, K) distance from (x, y) to each rectangle's edge; negative inside."""
    dx = np.maximum(rects[..., 0] - x[:, None], x[:, None] - rects[..., 1])
    dy = np.maximum(rects[..., 2] - y[:, None], y[:, None] - rects[..., 3])
    out = np.hypot(np.maximum(dx, 0.0), np.maximum(dy, 0.0))
    inside = np.maximum(dx, dy)
    return np.where(inside < 0, inside, out)


def inside_rect(x: np.ndarray, y: np.ndarray, rects: np.ndarray) -> np.ndarray:
    """(N, K) True where (x, y) lies inside the rectangle."""
    return (
        (x[:, None] >= rects[..., 0])
        & (x[:, None] <= rects[..., 1])
        & (y[:, None] >= rects[..., 2])
        & (y[:, None] <= rects[..., 3])
    )


def triangle_vertices(cx: np.ndarray, cy: np.ndarray, side: float | np.ndarray) -> np.ndarray:
    """(..., 3, 2) vertices of north-pointing equilateral triangles centred on (cx, cy), each of its own ``side``."""
    r = np.asarray(side, dtype=float)[..., None] / np.sqrt(3.0)  # circumradius, one per triangle
    angles = np.deg2rad([90.0, 210.0, 330.0])
    vx = cx[..., None] + r * np.cos(angles)
    vy = cy[..., None] + r * np.sin(angles)
    return np.stack([vx, vy], axis=-1)


def polygon_edges(vertices: np.ndarray) -> tuple[np.ndarray, ...]:
    """Precomputed edges of convex polygons (N, K, V, 2): (ax, ay, ex, ey, 1/|e|^2)."""
    ax, ay = vertices[..., 0], vertices[..., 1]
    ex, ey = np.roll(ax, -1, axis=-1) - ax, np.roll(ay, -1, axis=-1) - ay
    length2 = ex * ex + ey * ey
    return ax, ay, ex, ey, 1.0 / np.where(length2 > 0, length2, 1.0)


def polygon_signed_distance(
    x: np.ndarray, y: np.ndarray, vertices: np.ndarray | tuple
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Signed distance from (x, y) to convex polygons (N, K, V, 2, counter-clockwise).

    ``vertices`` may be the output of :func:`polygon_edges` (computed once per batch).
    Returns (distance, closest x, closest y), each (N, K); distance is negative inside.
    """
    ax, ay, ex, ey, inv = polygon_edges(vertices) if isinstance(vertices, np.ndarray) else vertices
    rx, ry = x[:, None, None] - ax, y[:, None, None] - ay
    t = np.clip((rx * ex + ry * ey) * inv, 0.0, 1.0)
    qx, qy = t * ex - rx, t * ey - ry  # closest edge point relative to (x, y)
    d2 = qx * qx + qy * qy
    V = d2.shape[-1]
    best = np.argmin(d2, axis=-1).ravel() + np.arange(0, d2.size, V)  # flat index of each closest edge
    dist = np.sqrt(d2.ravel()[best]).reshape(d2.shape[:-1])
    cx = x[:, None] + qx.ravel()[best].reshape(d2.shape[:-1])
    cy = y[:, None] + qy.ravel()[best].reshape(d2.shape[:-1])
    inside = np.all(ex * ry - ey * rx > 0, axis=-1)  # left of every CCW edge
    return np.where(inside, -dist, dist), cx, cy
