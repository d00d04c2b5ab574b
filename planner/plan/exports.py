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
per RFC 7946 (``[lon, lat]``, closed counter-clockwise rings), built by
:mod:`planner.common.geojson`, which the fly and review stages draw too.  Items run in the order
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

from planner.common.atomic import write_text_atomic
from planner.common.geojson import decode_scenario, exclusions, geojson, operational_rect, oriented, rect_vertices
from rapt.errors import InputError
from sim.uuv.geo import DEGREE_DECIMALS, LocalFrame
from sim.uuv.interface import DEPTH_M
from sim.uuv.mission import Mission
from sim.uuv.scenario import Scenarios

__all__ = ["qgc_plan", "wpl", "write_scenario_files"]

#: MAVLink values used in the files (MAV_CMD, MAV_FRAME, MAV_AUTOPILOT, MAV_TYPE).
MAV_CMD_NAV_WAYPOINT = 16
MAV_CMD_NAV_LOITER_TIME = 19
MAV_FRAME_GLOBAL = 0
MAV_FRAME_GLOBAL_RELATIVE_ALT = 3
MAV_AUTOPILOT_ARDUPILOTMEGA = 3
MAV_TYPE_SUBMARINE = 12
#: QGroundControl's AltMode enum: Relative.
QGC_ALT_MODE_RELATIVE = 1


@dataclass(frozen=True)
class _Item:
    """One mission item in the local frame: MAVLink command, params 1-4, position."""

    command: int
    params: tuple[float, float, float, float]
    x: float
    y: float


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


def _route_items(mission: Mission, scen: Scenarios, route) -> list[_Item]:
    """The scenario's items, or ``route``'s: (x, y, loiter seconds) points, the last one the recovery point."""
    if route is None:
        return _items(mission, scen)
    points = [(float(x), float(y), float(s)) for x, y, s in route]
    radius = [float(mission.waypoint_radius)] * (len(points) - 1) + [float(mission.recovery_radius)]
    return [
        _Item(MAV_CMD_NAV_LOITER_TIME, (s, 0.0, 0.0, 0.0), x, y)
        if s > 0
        else _Item(MAV_CMD_NAV_WAYPOINT, (0.0, r, 0.0, 0.0), x, y)
        for (x, y, s), r in zip(points, radius)
    ]


def _num(v: float) -> float | None:
    """A JSON number, or null for NaN/inf (the ``.plan`` convention)."""
    v = float(v)
    return v if math.isfinite(v) else None


def qgc_plan(mission: Mission, u, route=None) -> dict[str, Any]:
    """The QGroundControl ``.plan`` (a JSON-ready dict) of scenario ``u`` (shape (mission.dim,)).

    ``route`` ((x, y, loiter seconds) points ending at the recovery point) replaces the mission's
    items, e.g. with a calibration run's turn points (:mod:`planner.plan.shakedown`)."""
    scen = decode_scenario(mission, u)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    alt = -float(DEPTH_M)

    def latlon(x, y) -> list[float]:
        lat, lon = frame.to_latlon(float(x), float(y))
        return [round(lat, DEGREE_DECIMALS), round(lon, DEGREE_DECIMALS)]

    items = []
    for seq, it in enumerate(_route_items(mission, scen, route), start=1):
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
        cw = oriented(vertices, clockwise=True)
        return {"inclusion": inclusion, "polygon": [latlon(x, y) for x, y in cw], "version": 1}

    polygons = [polygon(rect_vertices(operational_rect(mission)), True)]
    polygons += [polygon(v, False) for _, _, v in exclusions(mission, scen)]
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


def wpl(mission: Mission, u, route=None) -> str:
    """The ``QGC WPL 110`` text of scenario ``u``: home (the launch point) then the ``.plan`` items (``route``'s
    when given, see :func:`qgc_plan`)."""
    scen = decode_scenario(mission, u)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)

    def line(seq, current, mav_frame, command, params, x, y, alt) -> str:
        lat, lon = frame.to_latlon(float(x), float(y))
        fields = [str(seq), str(current), str(mav_frame), str(command)]
        fields += [f"{float(p):.6f}" for p in params]
        fields += [f"{lat:.8f}", f"{lon:.8f}", f"{float(alt):.6f}", "1"]
        return "\t".join(fields)

    lines = ["QGC WPL 110", line(0, 1, MAV_FRAME_GLOBAL, MAV_CMD_NAV_WAYPOINT, (0, 0, 0, 0), *mission.launch, 0.0)]
    for seq, it in enumerate(_route_items(mission, scen, route), start=1):
        lines.append(line(seq, 0, MAV_FRAME_GLOBAL_RELATIVE_ALT, it.command, it.params, it.x, it.y, -DEPTH_M))
    return "\n".join(lines) + "\n"


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
        write_text_atomic(paths[suffix], text)
    return paths
