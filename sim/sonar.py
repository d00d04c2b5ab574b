"""Forward-looking obstacle sonar: the closest point of each obstacle in range and field of view.

Obstacles are unknown to the autonomy until the sonar sees them (section 3.7.1), so
avoidance starts late on a fast vehicle and an obstacle beside the path may never be
seen: both shape the collision boundaries.  The same signed distances decide collisions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.geometry import polygon_signed_distance, rect_closest_point, rect_signed_distance
from sim.mission import Vehicle
from sim.vehicle import wrap_angle

__all__ = ["Contacts", "sense"]


@dataclass
class Contacts:
    """(N, K) closest points, signed distances and detection flags; K = obstacles + barriers."""

    x: np.ndarray
    y: np.ndarray
    distance: np.ndarray
    detected: np.ndarray


def sense(x: np.ndarray, y: np.ndarray, heading: np.ndarray, obstacles, barriers: np.ndarray,
          spec: Vehicle) -> Contacts:
    """Contacts of every triangle obstacle (N, T, 3, 2, or its precomputed edges) and barrier (N, B, 4)."""
    parts = []
    if (obstacles.shape[1] if isinstance(obstacles, np.ndarray) else obstacles[0].shape[1]):
        parts.append(polygon_signed_distance(x, y, obstacles))
    if barriers.shape[1]:
        cx, cy = rect_closest_point(x, y, barriers)
        parts.append((rect_signed_distance(x, y, barriers), cx, cy))
    if not parts:
        e = np.zeros((x.shape[0], 0))
        return Contacts(e, e, e, e.astype(bool))
    d = np.concatenate([p[0] for p in parts], axis=1)
    cx = np.concatenate([p[1] for p in parts], axis=1)
    cy = np.concatenate([p[2] for p in parts], axis=1)
    bearing = np.arctan2(cx - x[:, None], cy - y[:, None])
    in_fov = np.abs(wrap_angle(bearing - heading[:, None])) <= np.deg2rad(spec.sonar_fov_deg) / 2
    detected = (d <= spec.sonar_range_m) & (in_fov | (d < 5.0))
    return Contacts(cx, cy, d, detected)
