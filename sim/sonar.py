"""Forward-looking obstacle sonar: the closest point of each obstacle in range and field of view.

Obstacles are unknown to the autonomy until the sonar sees them (section 3.7.1), so
avoidance starts late on a fast vehicle and an obstacle beside the path may never be
seen: both shape the collision boundaries.  The same signed distances decide collisions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.geometry import polygon_edges, polygon_signed_distance, rect_closest_point, rect_signed_distance
from sim.mission import Vehicle
from sim.vehicle import wrap_angle

__all__ = ["Contacts", "sense", "scan", "SCAN_BEAMS", "SCAN_RESOLUTION_M", "BEAMS_PER_MESSAGE"]


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


#: Beams of the imitation features' sonar scan: 360 at 1 degree (section 6.5.3).
SCAN_BEAMS = 360
#: Scan ranges are reported in whole centimetres (OBSTACLE_DISTANCE carries uint16 cm).
SCAN_RESOLUTION_M = 0.01
#: OBSTACLE_DISTANCE carries 72 distances; a 360-beam scan takes five messages.
BEAMS_PER_MESSAGE = 72


def _ray_hits(px, py, bearing, ax, ay, ex, ey) -> np.ndarray:
    """Distance along rays (P, B) from (px, py) to segments (P, E) a + s e; inf where missed."""
    dx, dy = np.sin(bearing)[:, :, None], np.cos(bearing)[:, :, None]  # (P, B, 1)
    wx, wy = (ax - px[:, None])[:, None, :], (ay - py[:, None])[:, None, :]  # (P, 1, E)
    ex, ey = ex[:, None, :], ey[:, None, :]
    den = dx * ey - dy * ex
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    t = (wx * ey - wy * ex) / den
    s = (wx * dy - wy * dx) / den
    hit = ok & (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
    return np.where(hit, t, np.inf).min(axis=2)


def scan(x: np.ndarray, y: np.ndarray, heading: np.ndarray, obstacles, barriers: np.ndarray, range_m: float,
         beams: int = SCAN_BEAMS) -> np.ndarray:
    """A 360-degree range scan (N, beams): beam b looks ``b * 360 / beams`` degrees clockwise of the bow.

    Ranges are to the first obstacle or barrier edge in whole centimetres (divided by 100,
    as a receiver of OBSTACLE_DISTANCE computes them); a beam that sees nothing reads
    ``range_m + 0.01`` (MAVLink's "max + 1": no obstacle), and a vehicle
    inside an obstacle reads 0 on every beam.  Only obstacles within range are ray-cast,
    so a vehicle in open water costs one distance check per obstacle.
    """
    n = x.shape[0]
    out = np.full((n, beams), np.inf)
    rel = np.deg2rad(np.arange(beams) * (360.0 / beams))
    inside = np.zeros(n, dtype=bool)
    shapes = []
    if (obstacles.shape[1] if isinstance(obstacles, np.ndarray) else obstacles[0].shape[1]):
        ax, ay, ex, ey, _ = polygon_edges(obstacles) if isinstance(obstacles, np.ndarray) else obstacles
        d = polygon_signed_distance(x, y, (ax, ay, ex, ey, _))[0]
        shapes.append((d, ax, ay, ex, ey))
    if barriers.shape[1]:
        x0, x1, y0, y1 = (barriers[..., k] for k in range(4))
        ax = np.stack([x0, x1, x1, x0], axis=-1)
        ay = np.stack([y0, y0, y1, y1], axis=-1)
        ex = np.roll(ax, -1, axis=-1) - ax
        ey = np.roll(ay, -1, axis=-1) - ay
        shapes.append((rect_signed_distance(x, y, barriers), ax, ay, ex, ey))
    for d, ax, ay, ex, ey in shapes:
        inside |= np.any(d <= 0, axis=1)
        rows, ks = np.nonzero((d <= range_m) & (d > 0))
        if rows.size == 0:
            continue
        bearing = heading[rows, None] + rel[None, :]
        hits = _ray_hits(x[rows], y[rows], bearing, ax[rows, ks], ay[rows, ks], ex[rows, ks], ey[rows, ks])
        np.minimum.at(out, rows, hits)
    cm = np.where(out <= range_m, np.round(out * 100.0), np.floor(range_m * 100.0) + 1.0)
    cm[inside] = 0.0
    return cm / 100.0  # as a receiver of OBSTACLE_DISTANCE's uint16 centimetres computes it
