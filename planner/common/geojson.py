"""The GeoJSON picture of one scenario: its mission elements and, when given, the predicted track.

Planning writes it as the range's ``.geojson`` file (:mod:`planner.plan.exports`), flying puts it
on the bus for the log's map (:mod:`planner.fly.scenario_map`), and reviewing draws it under the
observed tracks (:mod:`planner.review.overlay`): one document, built here, so the three never
disagree.  It follows RFC 7946 (``[lon, lat]``, closed counter-clockwise rings).  The decoded
scenario and the polygons it is drawn from are shared with the ``.plan`` and ``QGC WPL 110``
exports, which draw the same elements.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rapt.errors import InputError
from sim.uuv.geo import DEGREE_DECIMALS, LocalFrame
from sim.uuv.mission import Mission
from sim.uuv.scenario import Scenarios, make_scenarios
from sim.uuv.simulate import TRAJECTORY_FIELDS

__all__ = ["decode_scenario", "rect_vertices", "oriented", "operational_rect", "exclusions", "geojson"]

_T, _X, _Y, _SURFACED = (TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "surfaced"))


def decode_scenario(mission: Mission, u) -> Scenarios:
    """The decoded scenario of row ``u``; raises if the row is malformed or the scenario invalid."""
    row = np.asarray(u, dtype=float)
    if row.shape != (mission.dim,):
        raise InputError(
            f"u: expected a unit-cube row of shape ({mission.dim},) for mission '{mission.name}', got {row.shape}"
        )
    if not np.all(np.isfinite(row)) or np.any(row < 0.0) or np.any(row > 1.0):
        raise InputError("u: values must be finite and inside the unit cube [0, 1]")
    scen = make_scenarios(mission, row[None, :])
    if not scen.valid[0]:
        raise InputError(f"u: scenario is invalid ({scen.invalid_reason[0]})")
    return scen


def rect_vertices(rect: np.ndarray) -> np.ndarray:
    """(4, 2) counter-clockwise corners of an (xmin, xmax, ymin, ymax) rectangle."""
    x0, x1, y0, y1 = (float(v) for v in rect)
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def oriented(vertices: np.ndarray, clockwise: bool) -> np.ndarray:
    """The polygon's vertices turning the requested way (x east, y north; a map seen from above)."""
    v = np.asarray(vertices, dtype=float)
    x, y = v[:, 0], v[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return v[::-1] if (area2 > 0) == clockwise else v


def operational_rect(mission: Mission) -> np.ndarray:
    r = mission.operational_area
    return np.array([r.x - r.width / 2, r.x + r.width / 2, r.y - r.height / 2, r.y + r.height / 2])


def exclusions(mission: Mission, scen: Scenarios) -> list[tuple[str, str, np.ndarray]]:
    """(kind, name, vertices) of every no-go area, barrier and obstacle at its scenario position."""
    out = [("nogo", z.name, rect_vertices(scen.nogo[0, k])) for k, z in enumerate(mission.nogo)]
    out += [("barrier", b.name, rect_vertices(scen.barriers[0, k])) for k, b in enumerate(mission.barriers)]
    out += [("obstacle", o.name, scen.obstacles[0, k]) for k, o in enumerate(mission.obstacles)]
    return out


def _check_track(track) -> np.ndarray:
    tr = np.asarray(track, dtype=float)
    if tr.ndim != 2 or tr.shape[1] != len(TRAJECTORY_FIELDS) or tr.shape[0] < 2:
        raise InputError(
            f"track: expected a trajectory of shape (steps >= 2, {len(TRAJECTORY_FIELDS)}) "
            f"with columns {TRAJECTORY_FIELDS}, got {tr.shape}"
        )
    if not np.all(np.isfinite(tr[:, [_T, _X, _Y]])):
        raise InputError("track: t, x and y must be finite")
    return tr


def geojson(mission: Mission, u, track=None) -> dict[str, Any]:
    """An RFC 7946 FeatureCollection of scenario ``u``, with the predicted ``track`` when given.

    ``track`` is one trajectory of :func:`sim.uuv.simulate` (``trajectories=True``).
    """
    scen = decode_scenario(mission, u)
    tr = None if track is None else _check_track(track)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)

    def lonlat(xy: np.ndarray) -> list[list[float]]:
        lat, lon = frame.to_latlon(np.asarray(xy[:, 0], float), np.asarray(xy[:, 1], float))
        return [
            [round(float(a), DEGREE_DECIMALS), round(float(b), DEGREE_DECIMALS)]
            for a, b in zip(np.atleast_1d(lon), np.atleast_1d(lat))
        ]

    def feature(geometry: dict, kind: str, name: str, **extra) -> dict[str, Any]:
        return {"type": "Feature", "geometry": geometry, "properties": {"kind": kind, "name": name, **extra}}

    def point(x, y, kind, name, **extra):
        return feature({"type": "Point", "coordinates": lonlat(np.array([[x, y]]))[0]}, kind, name, **extra)

    def polygon(vertices, kind, name, **extra):
        ring = lonlat(oriented(vertices, clockwise=False))
        return feature({"type": "Polygon", "coordinates": [ring + [ring[0]]]}, kind, name, **extra)

    feats = [
        point(*mission.launch, "launch", "launch"),
        point(*mission.recovery, "recovery", "recovery", radius_m=float(mission.recovery_radius)),
    ]
    feats += [point(x, y, "waypoint", str(i)) for i, (x, y) in enumerate(scen.waypoints)]
    feats.append(polygon(rect_vertices(operational_rect(mission)), "operational_area", mission.operational_area.name))
    rank = {int(a): r for r, a in enumerate(scen.order[0].tolist(), start=1)}
    feats += [
        polygon(
            rect_vertices(scen.area_rect[0, k]),
            "mission_area",
            a.name,
            priority=rank[k],
            dwell_s=float(scen.area_dwell[0, k]),
        )
        for k, a in enumerate(mission.mission_areas)
    ]
    if mission.transmission is not None:
        feats.append(
            polygon(
                rect_vertices(scen.tx_rect[0]),
                "transmission",
                mission.transmission.name,
                window_open_s=float(scen.tx_open[0]),
                window_close_s=float(scen.tx_close[0]),
                duration_s=float(mission.transmission.duration_s),
            )
        )
    feats += [polygon(v, kind, name) for kind, name, v in exclusions(mission, scen)]
    if tr is not None:
        t = tr[:, _T]
        surfaced_s = float(np.sum(np.diff(t) * (tr[:-1, _SURFACED] > 0.5)))
        feats.append(
            feature(
                {"type": "LineString", "coordinates": lonlat(tr[:, [_X, _Y]])},
                "predicted_track",
                "predicted track",
                duration_s=float(t[-1] - t[0]),
                surfaced_s=surfaced_s,
            )
        )
    return {"type": "FeatureCollection", "features": feats}
