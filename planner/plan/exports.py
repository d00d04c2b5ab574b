"""The files a range loads for one scenario: QGroundControl ``.plan``, ``QGC WPL 110`` and GeoJSON.

A field plan names scenarios as unit-cube rows; the range crew needs them in the tools
they already run.  QGroundControl and Mission Planner load a mission (plus fence and
rally point) to check and upload to the vehicle, and any GIS viewer shows the GeoJSON
picture of the range with the simulator's predicted track.  All three are built from the
same decoded scenario (:func:`sim.uuv.scenario.make_scenarios`) and the same list of mission
items, so the files never disagree with each other or with what was simulated.

Formats follow CONVENTIONS section 5: ``.plan`` version 1 with mission v2, geoFence v2
(polygon items v1, clockwise ``[lat, lon]`` vertices) and rallyPoints v2; WPL lines of 12
tab-separated fields with latitude before longitude and line 0 the home position; GeoJSON
per RFC 7946 (``[lon, lat]``, closed counter-clockwise rings).  Items run in the order
the autonomy means to fly them: waypoints, mission areas in the scenario's priority
order (loiter for the dwell time), the transmission area (loiter for the transmission
duration), then the recovery point.  The real autonomy transmits whenever the window is
open, so the transmission item's place in the list is nominal.  Depth is
:data:`sim.uuv.interface.DEPTH_M`, written as a negative relative altitude (ArduSub).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rapt.errors import InputError
from sim.uuv.geo import LocalFrame
from sim.uuv.interface import DEPTH_M
from sim.uuv.mission import Mission
from sim.uuv.scenario import Scenarios, make_scenarios
from sim.uuv.simulate import TRAJECTORY_FIELDS

__all__ = ["qgc_plan", "wpl", "geojson", "write_scenario_files"]

#: MAVLink values used in the files (MAV_CMD, MAV_FRAME, MAV_AUTOPILOT, MAV_TYPE).
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_TIME = 19
MAV_FRAME_GLOBAL = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_TYPE_SUBMARINE = 12
#: QGroundControl's AltMode enum: Relative.
QGC_ALT_MODE_RELATIVE = 1

_T, _X, _Y, _SURFACED = (TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "surfaced"))


@dataclass(frozen=True)
class _Item:
    """One mission item in the local frame: MAVLink command, params 1-4, position."""

    command: int
    params: tuple[float, float, float, float]
    x: float
    y: float


def _scenario(mission: Mission, u) -> Scenarios:
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


def _centre(rect: np.ndarray) -> tuple[float, float]:
    """Centre of an (xmin, xmax, ymin, ymax) rectangle."""
    return float((rect[0] + rect[1]) / 2.0), float((rect[2] + rect[3]) / 2.0)


def _items(mission: Mission, scen: Scenarios) -> list[_Item]:
    """Mission items in flying order (see the module docstring)."""
    items = [
        _Item(MAV_CMD_NAV_WAYPOINT, (0.0, float(mission.waypoint_radius), 0.0, 0.0), float(x), float(y))
        for x, y in scen.waypoints
    ]
    for a in scen.order[0].tolist():
        x, y = _centre(scen.area_rect[0, a])
        items.append(_Item(MAV_CMD_NAV_LOITER_TIME, (float(scen.area_dwell[0, a]), 0.0, 0.0, 0.0), x, y))
    if mission.transmission is not None:
        x, y = _centre(scen.tx_rect[0])
        items.append(_Item(MAV_CMD_NAV_LOITER_TIME, (float(mission.transmission.duration_s), 0.0, 0.0, 0.0), x, y))
    rx, ry = mission.recovery
    items.append(_Item(MAV_CMD_NAV_WAYPOINT, (0.0, float(mission.recovery_radius), 0.0, 0.0), float(rx), float(ry)))
    return items


def _num(v: float) -> float | None:
    """A JSON number, or null for NaN/inf (the ``.plan`` convention)."""
    v = float(v)
    return v if math.isfinite(v) else None


def _rect_vertices(rect: np.ndarray) -> np.ndarray:
    """(4, 2) counter-clockwise corners of an (xmin, xmax, ymin, ymax) rectangle."""
    x0, x1, y0, y1 = (float(v) for v in rect)
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def _oriented(vertices: np.ndarray, clockwise: bool) -> np.ndarray:
    """The polygon's vertices turning the requested way (x east, y north; a map seen from above)."""
    v = np.asarray(vertices, dtype=float)
    x, y = v[:, 0], v[:, 1]
    area2 = float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    return v[::-1] if (area2 > 0) == clockwise else v


def _op_rect(mission: Mission) -> np.ndarray:
    r = mission.operational_area
    return np.array([r.x - r.width / 2, r.x + r.width / 2, r.y - r.height / 2, r.y + r.height / 2])


def _exclusions(mission: Mission, scen: Scenarios) -> list[tuple[str, str, np.ndarray]]:
    """(kind, name, vertices) of every no-go area, barrier and obstacle at its scenario position."""
    out = [("nogo", z.name, _rect_vertices(scen.nogo[0, k])) for k, z in enumerate(mission.nogo)]
    out += [("barrier", b.name, _rect_vertices(scen.barriers[0, k])) for k, b in enumerate(mission.barriers)]
    out += [("obstacle", o.name, scen.obstacles[0, k]) for k, o in enumerate(mission.obstacles)]
    return out


def qgc_plan(mission: Mission, u) -> dict[str, Any]:
    """The QGroundControl ``.plan`` (a JSON-ready dict) of scenario ``u`` (shape (mission.dim,))."""
    scen = _scenario(mission, u)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    alt = -float(DEPTH_M)

    def latlon(x, y) -> list[float]:
        lat, lon = frame.to_latlon(float(x), float(y))
        return [lat, lon]

    items = []
    for seq, it in enumerate(_items(mission, scen), start=1):
        items.append(
            {
                "AMSLAltAboveTerrain": None,
                "Altitude": alt,
                "AltitudeMode": QGC_ALT_MODE_RELATIVE,
                "autoContinue": True,
                "command": it.command,
                "doJumpId": seq,
                "frame": MAV_FRAME_GLOBAL_RELATIVE_ALT,
                "params": [_num(p) for p in it.params] + latlon(it.x, it.y) + [alt],
                "type": "SimpleItem",
            }
        )

    def polygon(vertices: np.ndarray, inclusion: bool) -> dict[str, Any]:
        cw = _oriented(vertices, clockwise=True)
        return {"inclusion": inclusion, "polygon": [latlon(x, y) for x, y in cw], "version": 1}

    polygons = [polygon(_rect_vertices(_op_rect(mission)), True)]
    polygons += [polygon(v, False) for _, _, v in _exclusions(mission, scen)]
    return {
        "fileType": "Plan",
        "geoFence": {"circles": [], "polygons": polygons, "version": 2},
        "groundStation": "RAPT",
        "mission": {
            "cruiseSpeed": float(mission.vehicle.cruise_speed),
            "firmwareType": MAV_AUTOPILOT_ARDUPILOTMEGA,
            "globalPlanAltitudeMode": QGC_ALT_MODE_RELATIVE,
            "hoverSpeed": 0,
            "items": items,
            "plannedHomePosition": latlon(*mission.launch) + [0],
            "vehicleType": MAV_TYPE_SUBMARINE,
            "version": 2,
        },
        "rallyPoints": {"points": [latlon(*mission.recovery) + [0]], "version": 2},
        "version": 1,
    }


def wpl(mission: Mission, u) -> str:
    """The ``QGC WPL 110`` text of scenario ``u``: home (the launch point) then the ``.plan`` items."""
    scen = _scenario(mission, u)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)

    def line(seq, current, mav_frame, command, params, x, y, alt) -> str:
        lat, lon = frame.to_latlon(float(x), float(y))
        fields = [str(seq), str(current), str(mav_frame), str(command)]
        fields += [f"{float(p):.6f}" for p in params]
        fields += [f"{lat:.8f}", f"{lon:.8f}", f"{float(alt):.6f}", "1"]
        return "\t".join(fields)

    lines = ["QGC WPL 110", line(0, 1, MAV_FRAME_GLOBAL, MAV_CMD_NAV_WAYPOINT, (0, 0, 0, 0), *mission.launch, 0.0)]
    for seq, it in enumerate(_items(mission, scen), start=1):
        lines.append(line(seq, 0, MAV_FRAME_GLOBAL_RELATIVE_ALT, it.command, it.params, it.x, it.y, -DEPTH_M))
    return "\n".join(lines) + "\n"


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
    scen = _scenario(mission, u)
    tr = None if track is None else _check_track(track)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)

    def lonlat(xy: np.ndarray) -> list[list[float]]:
        lat, lon = frame.to_latlon(np.asarray(xy[:, 0], float), np.asarray(xy[:, 1], float))
        return [[float(a), float(b)] for a, b in zip(np.atleast_1d(lon), np.atleast_1d(lat))]

    def feature(geometry: dict, kind: str, name: str, **extra) -> dict[str, Any]:
        return {"type": "Feature", "geometry": geometry, "properties": {"kind": kind, "name": name, **extra}}

    def point(x, y, kind, name, **extra):
        return feature({"type": "Point", "coordinates": lonlat(np.array([[x, y]]))[0]}, kind, name, **extra)

    def polygon(vertices, kind, name, **extra):
        ring = lonlat(_oriented(vertices, clockwise=False))
        return feature({"type": "Polygon", "coordinates": [ring + [ring[0]]]}, kind, name, **extra)

    feats = [
        point(*mission.launch, "launch", "launch"),
        point(*mission.recovery, "recovery", "recovery", radius_m=float(mission.recovery_radius)),
    ]
    feats += [point(x, y, "waypoint", str(i)) for i, (x, y) in enumerate(scen.waypoints)]
    feats.append(polygon(_rect_vertices(_op_rect(mission)), "operational_area", mission.operational_area.name))
    rank = {int(a): r for r, a in enumerate(scen.order[0].tolist(), start=1)}
    feats += [
        polygon(
            _rect_vertices(scen.area_rect[0, k]),
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
                _rect_vertices(scen.tx_rect[0]),
                "transmission",
                mission.transmission.name,
                window_open_s=float(scen.tx_open[0]),
                window_close_s=float(scen.tx_close[0]),
                duration_s=float(mission.transmission.duration_s),
            )
        )
    feats += [polygon(v, kind, name) for kind, name, v in _exclusions(mission, scen)]
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


def write_scenario_files(mission: Mission, u, directory, stem: str, track=None) -> dict[str, Path]:
    """Write ``<stem>.plan``, ``<stem>.waypoints`` and ``<stem>.geojson`` into ``directory``.

    Returns their paths keyed ``"plan"``, ``"waypoints"`` and ``"geojson"``.  Everything is
    built before anything is written, so an invalid scenario leaves no files behind.
    """
    if not isinstance(stem, str) or not stem or Path(stem).name != stem or stem in (".", ".."):
        raise InputError(f"stem: expected a plain file name without directories, got {stem!r}")
    texts = {
        "plan": json.dumps(qgc_plan(mission, u), indent=4, allow_nan=False) + "\n",
        "waypoints": wpl(mission, u),
        "geojson": json.dumps(geojson(mission, u, track), indent=1, allow_nan=False) + "\n",
    }
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for suffix, text in texts.items():
        paths[suffix] = out / f"{stem}.{suffix}"
        paths[suffix].write_text(text, encoding="utf-8")
    return paths
