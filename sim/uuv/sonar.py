"""Forward-looking obstacle sonar: the closest point of each obstacle in range and field of view.

Obstacles are unknown to the autonomy until the sonar sees them (section 3.7.1), so
avoidance starts late on a fast vehicle and an obstacle beside the path may never be
seen: both shape the collision boundaries.  The same signed distances decide collisions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.uuv.angles import wrap_angle
from sim.uuv.geometry import polygon_edges, polygon_signed_distance, rect_closest_point, rect_signed_distance
from sim.uuv.mission import Vehicle

__all__ = ["Contacts", "sense", "scan", "SCAN_BEAMS", "SCAN_RESOLUTION_M", "BEAMS_PER_MESSAGE"]


@dataclass
class Contacts:
    """(N, K) closest points, signed distances and detection flags; K = obstacles + barriers."""

    x: np.ndarray
    y: np.ndarray
    distance: np.ndarray
    detected: np.ndarray


def sense(
    x: np.ndarray, y: np.ndarray, heading: np.ndarray, obstacles, barriers: np.ndarray, spec: Vehicle
) -> Contacts:
    """Contacts of every triangle obstacle (N, T, 3, 2, or its precomputed edges) and barrier (N, B, 4)."""
    parts = []
    if obstacles.shape[1] if isinstance(obstacles, np.ndarray) else obstacles[0].shape[1]:
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
    """Distance along rays (M,) from (px, py) to the first of segments (M, E) a + s e; inf where missed."""
    dx, dy = np.sin(bearing)[:, None], np.cos(bearing)[:, None]  # (M, 1)
    wx, wy = ax - px[:, None], ay - py[:, None]  # (M, E)
    den = dx * ey - dy * ex
    ok = np.abs(den) > 1e-12
    den = np.where(ok, den, 1.0)
    t = (wx * ey - wy * ex) / den
    s = (wx * dy - wy * dx) / den
    hit = ok & (t >= 0.0) & (s >= 0.0) & (s <= 1.0)
    return np.where(hit, t, np.inf).min(axis=1)


def scan(
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    obstacles,
    barriers: np.ndarray,
    range_m: float,
    beams: int = SCAN_BEAMS,
) -> np.ndarray:
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
    if obstacles.shape[1] if isinstance(obstacles, np.ndarray) else obstacles[0].shape[1]:
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
    step = 2.0 * np.pi / beams
    for d, ax, ay, ex, ey in shapes:
        inside |= np.any(d <= 0, axis=1)
        rows, ks = np.nonzero((d <= range_m) & (d > 0))
        if rows.size == 0:
            continue
        # only the beams that can meet the shape: within its angular radius of its centre's bearing
        vx, vy = ax[rows, ks], ay[rows, ks]  # (P, E) vertices
        cx, cy = vx.mean(axis=1), vy.mean(axis=1)
        radius = np.hypot(vx - cx[:, None], vy - cy[:, None]).max(axis=1)
        dist = np.hypot(cx - x[rows], cy - y[rows])
        half = np.where(
            dist > radius, np.arcsin(np.clip(radius / np.maximum(dist, 1e-9), 0.0, 1.0)) + 2 * step, np.pi
        )  # inside the shape's circumcircle it may fill any beam
        off = np.mod(np.arctan2(cx - x[rows], cy - y[rows]) - heading[rows], 2 * np.pi)  # centre, from the bow
        gap = np.abs(wrap_angle(rel[None, :] - off[:, None]))  # (P, beams)
        pi, bi = np.nonzero(gap <= half[:, None])
        if pi.size == 0:
            continue
        hits = _ray_hits(
            x[rows[pi]],
            y[rows[pi]],
            heading[rows[pi]] + rel[bi],
            vx[pi],
            vy[pi],
            ex[rows[pi], ks[pi]],
            ey[rows[pi], ks[pi]],
        )
        np.minimum.at(out, (rows[pi], bi), hits)
    cm = np.where(out <= range_m, np.round(out * 100.0), np.floor(range_m * 100.0) + 1.0)
    cm[inside] = 0.0
    return cm / 100.0  # as a receiver of OBSTACLE_DISTANCE's uint16 centimetres computes it
