"""A calibration run ("shakedown"): one run of legs that identify the vehicle, designed to fit the range.

Before the boundary scenarios fly, the range day starts with a run whose every leg tells the
calibration fit (``rapt-plan calibrate``) something about the vehicle: straight legs at four
commanded speeds spanning its range and beyond its saturation (half cruise, cruise,
``max_speed`` and :data:`OVER_MAX` times it), each :data:`SETTLE_TAUS` surge time constants to
reach steady speed plus a measured stretch; 180-degree turns both ways at the turn-rate
limit; a hold at speed 0 (hotel and depth-keeping draw); an ascent to the surface that goes on
at cruise speed there (what a thruster vehicle makes at the surface, and draws), and a dive
back; and the way home to the recovery point, ending surfaced there (:mod:`sim.uuv.legs`).

The legs run out and back along one bearing from the launch point (a racetrack whose
turns are only a turning circle wide).  Bearings are tried in order of the free distance
from the launch point along them; each is flown in the batch simulator on the scenario row
the run is flown on (the centre of the unit cube), and the first whose whole predicted track
keeps :attr:`ShakedownOptions.margin_m` from the operational area's edge, every no-go area,
barrier and obstacle, ends recovered and within the time allowed is the design.  When none
does, one line names what is in the way of the best bearing and the fix.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

import sim.uuv
from planner.common.geojson import geojson
from planner.common.jsonio import jsonable
from planner.common.plans import PLAN_SCHEMA, embedded_mission
from planner.plan.exports import qgc_plan, wpl
from rapt.errors import InputError, StudyMismatchError
from sim.uuv.geo import DEGREE_DECIMALS, LocalFrame
from sim.uuv.geometry import polygon_signed_distance, rect_signed_distance
from sim.uuv.legs import Leg, LegAutonomy, leg_schedule
from sim.uuv.metrics import MISSION_NODES, ROOT, SAFETY_NODES
from sim.uuv.mission import Mission
from sim.uuv.missionfile import load_mission_text
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import MODE_NAMES
from sim.uuv.simulate import TRAJECTORY_FIELDS

__all__ = [
    "ShakedownOptions",
    "ShakedownDesign",
    "design_shakedown",
    "shakedown_legs",
    "shakedown_plan",
    "write_shakedown",
    "SCENARIO_ID",
    "ROW",
]

#: The calibration run's scenario id in its plan.
SCENARIO_ID = "shakedown"
#: Which scenario row the run is flown on (recorded in the plan).
ROW = "centre of the unit cube"
#: Commanded speed of the fastest leg, times max_speed (beyond the speed loop's saturation).
OVER_MAX = 1.3
#: Surge time constants each speed leg allows to reach steady speed before its measured stretch.
SETTLE_TAUS = 5.0
#: Seconds of the ascent leg (rising at ~0.5 m/s from 2 m, then about 45 s at cruise at the
#: surface: :data:`planner.review.calibration_terms.SURFACE_SETTLE_S` to slow down, the rest measured).
SURFACE_S = 60.0
#: Seconds to dive back (a real vehicle dives at ~0.5 m/s).
DIVE_S = 30.0
#: Bearings tried, degrees apart.
BEARING_STEP_DEG = 15.0
_T, _X, _Y, _HEADING, _SPEED, _SURFACED = (
    TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "heading", "speed", "surfaced")
)


@dataclass(frozen=True)
class ShakedownOptions:
    """How long the run may last (vehicle minutes), its clearance from everything (m), each leg's measured stretch (s)."""

    max_minutes: float = 15.0
    margin_m: float = 50.0
    measure_s: float = 60.0

    def check(self) -> None:
        for value, flag in (
            (self.max_minutes, "--max-minutes"),
            (self.margin_m, "--margin"),
            (self.measure_s, "--measure-s"),
        ):
            if not (np.isfinite(value) and value > 0):
                raise InputError(f"{flag}: expected a number > 0, got {value}")


@dataclass(frozen=True)
class ShakedownDesign:
    """The designed run: its row, bearing, legs with their predicted times, and the predicted run."""

    mission: Mission
    u: np.ndarray
    bearing_deg: float
    legs: tuple[Leg, ...]
    starts: np.ndarray  # (legs,) predicted start of each leg, mission seconds
    end_s: float  # predicted end: surfaced at the recovery point
    track: np.ndarray  # the predicted trajectory (TRAJECTORY_FIELDS columns)
    mode: str
    scores: dict[str, float]  # the score tree's top two levels
    clearance: dict[str, float]  # closest approach of the track to each element kind (m)
    options: ShakedownOptions

    def leg_entries(self) -> list[dict]:
        """Each leg with its predicted start and end (mission seconds), as plan.json and the log record it."""
        ends = list(self.starts[1:]) + [self.end_s]
        return [
            {**jsonable(vars(leg)), "start_s": float(s), "end_s": float(e)}
            for leg, s, e in zip(self.legs, self.starts, ends)
        ]

    def turn_points(self) -> list[tuple[float, float, float]]:
        """(x, y, loiter seconds) where each leg begins on the predicted track, then the recovery point."""
        t = self.track[:, _T]
        out = []
        for leg, s in zip(self.legs, self.starts):
            k = min(int(np.searchsorted(t, s)), len(t) - 1)
            out.append(
                (float(self.track[k, _X]), float(self.track[k, _Y]), leg.duration_s if leg.kind == "hold" else 0.0)
            )
        rx, ry = self.mission.recovery
        return out + [(float(rx), float(ry), 0.0)]


def shakedown_legs(mission: Mission, bearing_deg: float, options: ShakedownOptions) -> tuple[Leg, ...]:
    """The legs of a run out along ``bearing_deg`` from the launch point and back (module docstring)."""
    v = mission.vehicle
    b, back = float(bearing_deg) % 360.0, (float(bearing_deg) + 180.0) % 360.0
    run_s = SETTLE_TAUS * v.surge_time_constant_s + options.measure_s
    rate = v.max_turn_rate_dps
    turn_s = 180.0 / (3.0 * rate) + 180.0 / rate + 3.0 * v.yaw_time_constant_s + 2.0 * v.heading_time_s
    slow = 0.5 * v.cruise_speed
    legs = [
        Leg("straight", "half_cruise", run_s, slow, b),
        Leg("straight", "cruise", run_s, v.cruise_speed, b),
        Leg("turn", "turn_right", turn_s, v.cruise_speed, back, 180.0),
        Leg("straight", "max_speed", run_s, v.max_speed, back),
        Leg("turn", "turn_left", turn_s, v.cruise_speed, b, -180.0),
        Leg("straight", "over_max", run_s, OVER_MAX * v.max_speed, b),
        Leg("hold", "hold", run_s, 0.0, b),
        Leg("ascent", "ascent", SURFACE_S, v.cruise_speed, b, surface=True),
        Leg("dive", "dive", DIVE_S, slow, b),
    ]
    used = float(sum(leg.duration_s for leg in legs))
    limit = min(60.0 * options.max_minutes, mission.time_limit_s)
    if used >= limit:
        raise InputError(
            f"--max-minutes: the calibration legs alone take {used / 60:.1f} min, more than the {limit / 60:.1f} min "
            f"allowed (--max-minutes {options.max_minutes:g}, mission time limit {mission.time_limit_s:g} s); "
            "raise --max-minutes or shorten the legs with --measure-s"
        )
    return tuple(legs) + (Leg("return", "return", limit - used, v.cruise_speed),)


def _unit_row(mission: Mission) -> np.ndarray:
    u = mission.space.snap(np.full((1, mission.dim), 0.5))[0]  # the ranges' centres, as the range sets them
    scen = make_scenarios(mission, u[None, :])
    if not scen.valid[0]:
        raise InputError(
            f"MISSION_FILE: the {ROW} is not a valid scenario of '{mission.name}' ({scen.invalid_reason[0]}); "
            "move the parameter ranges so that their centres make a valid range"
        )
    return u


def _distances(mission: Mission, scen, x: np.ndarray, y: np.ndarray) -> tuple[list[str], np.ndarray]:
    """What the points must keep clear of, and (points, what) their distances (m, negative inside):
    the operational area's edge, then each no-go area, barrier and obstacle of the scenario ``scen``."""
    n = x.shape[0]
    op = mission.operational_area
    x0, x1, y0, y1 = op.x - op.width / 2, op.x + op.width / 2, op.y - op.height / 2, op.y + op.height / 2
    names = ["the operational area's edge"]
    cols = [np.minimum(np.minimum(x - x0, x1 - x), np.minimum(y - y0, y1 - y))[:, None]]
    for kind, elements, rects in (
        ("no-go area", mission.nogo, scen.nogo),
        ("barrier", mission.barriers, scen.barriers),
    ):
        if elements:
            names += [f"{kind} {e.name}" for e in elements]
            cols.append(rect_signed_distance(x, y, np.broadcast_to(rects[0], (n,) + rects.shape[1:])))
    if mission.obstacles:
        names += [f"obstacle {o.name}" for o in mission.obstacles]
        verts = np.ascontiguousarray(np.broadcast_to(scen.obstacles[0], (n,) + scen.obstacles.shape[1:]))
        cols.append(polygon_signed_distance(x, y, verts)[0])
    return names, np.concatenate(cols, axis=1)


def _free_distance(mission: Mission, scen, bearing_deg: float, margin: float) -> float:
    """How far (m) from the launch point the ray along ``bearing_deg`` keeps ``margin`` from everything."""
    op = mission.operational_area
    s = np.arange(0.0, float(np.hypot(op.width, op.height)), 5.0)
    lx, ly = mission.launch
    b = np.deg2rad(bearing_deg)
    _, d = _distances(mission, scen, lx + s * np.sin(b), ly + s * np.cos(b))
    blocked = np.flatnonzero(d.min(axis=1) < margin)
    return float(s[blocked[0]]) if blocked.size else float(s[-1])


#: Bearings simulated at most, the most open first.
TRIED_BEARINGS = 8


def design_shakedown(mission: Mission, options: ShakedownOptions | None = None) -> ShakedownDesign:
    """The calibration run of ``mission`` (module docstring); InputError (one line) when none fits."""
    options = options or ShakedownOptions()
    options.check()
    u = _unit_row(mission)
    scen = make_scenarios(mission, u[None, :])
    bearings = np.arange(0.0, 360.0, BEARING_STEP_DEG)
    free = [_free_distance(mission, scen, float(b), options.margin_m) for b in bearings]
    order = sorted(range(len(bearings)), key=lambda k: (-free[k], k))[:TRIED_BEARINGS]
    first: tuple[float, float, str, str] | None = None
    for k in order:
        design = _fly(mission, u, scen, float(bearings[k]), options)
        found = _problem(design)
        if found is None:
            return design
        first = first or (float(bearings[k]), free[k], *found)
    assert first is not None
    bearing, clear, problem, fix = first
    raise InputError(
        f"shakedown: no calibration run fits mission '{mission.name}' from its launch point: along the most open "
        f"bearing ({bearing:.0f} deg, {clear:.0f} m clear) {problem}; {fix}"
    )


def _fly(mission: Mission, u: np.ndarray, scen, bearing: float, options: ShakedownOptions) -> ShakedownDesign:
    """The legs along ``bearing``, flown in the batch simulator on row ``u``."""
    legs = shakedown_legs(mission, bearing, options)
    result = sim.uuv.simulate(mission, u[None, :], trajectories=True, driver=lambda s: LegAutonomy(s, legs))
    track = result.trajectory(0)
    assert track is not None, "the row is valid"
    names, d = _distances(mission, scen, track[:, _X], track[:, _Y])
    levels = set(ROOT) | set(MISSION_NODES) | set(SAFETY_NODES)
    recovered = bool(result.column("recovery.time_s")[0] < mission.time_limit_s)
    return ShakedownDesign(
        mission,
        u,
        bearing,
        legs,
        leg_schedule(legs)[:-1],
        float(track[-1, _T]) if recovered else float("inf"),
        track,
        MODE_NAMES[int(result.modes[0])],
        {n: float(v) for n, v in zip(result.names, result.scores[0]) if n in levels},
        {n: float(v) for n, v in zip(names, d.min(axis=0))},
        options,
    )


def _problem(design: ShakedownDesign) -> tuple[str, str] | None:
    """What keeps a simulated design from flying, and the fix (None: it fits)."""
    o = design.options
    lever = f"lower --margin (now {o.margin_m:g}) or shorten the legs with --measure-s (now {o.measure_s:g})"
    worst = min(design.clearance, key=lambda k: design.clearance[k])
    if design.clearance[worst] < o.margin_m:
        fix = "give the launch point more room in the operational area" if "edge" in worst else f"move {worst}"
        d = design.clearance[worst]
        where = f"comes within {d:.0f} m of {worst}"
        if d < 0:
            where = (
                f"leaves the operational area ({-d:.0f} m out)"
                if "edge" in worst
                else f"crosses {worst} ({-d:.0f} m deep)"
            )
        return f"its track {where} (margin {o.margin_m:g} m)", f"{fix}, or {lever}"
    if not np.isfinite(design.end_s):
        return "its predicted run does not end surfaced at the recovery point", f"raise --max-minutes or {lever}"
    if design.end_s < design.starts[-1]:
        return (
            f"it surfaces at the recovery point at {design.end_s:.0f} s, before its return leg",
            "move the launch point away from the recovery point",
        )
    if design.end_s > 60.0 * o.max_minutes:
        return (
            f"its predicted run takes {design.end_s / 60:.1f} min",
            f"raise --max-minutes (now {o.max_minutes:g}) or shorten the legs with --measure-s",
        )
    return None


#: The predicted track's columns in plan.json.
TRACK_FIELDS = ("t", "x", "y", "heading", "speed", "surfaced")


def shakedown_plan(design: ShakedownDesign, mission_file: Path, mission_text: str) -> dict[str, Any]:
    """The calibration run's ``plan.json`` (a field plan with a ``calibration`` object):
    its one scenario ``shakedown`` with its row, legs and predicted run, flyable with ``rapt-plan run``."""
    m, o = design.mission, design.options
    cols = [TRAJECTORY_FIELDS.index(k) for k in TRACK_FIELDS]
    rows = [[round(float(v), 3) for v in row] for row in design.track[:, cols]]
    return {
        "schema": PLAN_SCHEMA,
        "mission": {
            "name": m.name,
            "file": str(mission_file),
            "dim": m.dim,
            "parameters": m.space.names,
            **embedded_mission(mission_text),
        },
        "calibration": {
            "kind": SCENARIO_ID,
            "row": ROW,
            "bearing_deg": design.bearing_deg,
            "max_minutes": o.max_minutes,
            "margin_m": o.margin_m,
            "measure_s": o.measure_s,
            "settle_s": SETTLE_TAUS * m.vehicle.surge_time_constant_s,
            "duration_s": design.end_s,
            "clearance_m": design.clearance,
        },
        "pairs": [],
        "scenarios": [
            {
                "id": SCENARIO_ID,
                "u": [float(v) for v in design.u],
                "parameters": jsonable(m.space.decode(design.u[None, :])[0]),
                "legs": design.leg_entries(),
                "predicted": {
                    "mode": design.mode,
                    "scores": design.scores,
                    "track": {"fields": list(TRACK_FIELDS), "rows": rows},
                },
                "files": {kind: f"{SCENARIO_ID}.{kind}" for kind in ("plan", "waypoints", "geojson")},
            }
        ],
        "variants": [],
        "run_order": [SCENARIO_ID],
    }


def _picture(design: ShakedownDesign) -> dict[str, Any]:
    """The GeoJSON of the run: the range, the predicted track and where each leg begins."""
    m = design.mission
    doc = geojson(m, design.u, design.track)
    frame = LocalFrame(m.origin_lat, m.origin_lon)
    for leg, (x, y, _) in zip(design.legs, design.turn_points()):
        lat, lon = frame.to_latlon(x, y)
        doc["features"].append(
            {
                "type": "Feature",
                "geometry": {
                    "type": "Point",
                    "coordinates": [round(float(lon), DEGREE_DECIMALS), round(float(lat), DEGREE_DECIMALS)],
                },
                "properties": {"kind": "leg", "name": leg.name, "leg_kind": leg.kind},
            }
        )
    return doc


def write_shakedown(design: ShakedownDesign, mission_file: Path, out_dir: Path) -> Path:
    """Write ``plan.json`` and the run's ``.plan``, ``.waypoints`` and ``.geojson`` into ``out_dir``; each file is
    written whole or not at all, and all of them are built before the first is written."""
    m = design.mission
    try:
        text = Path(mission_file).read_bytes().decode("utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"MISSION_FILE: cannot read {mission_file} to embed it in the plan ({exc})") from None
    if load_mission_text(text, str(mission_file)) != m:
        raise StudyMismatchError(f"MISSION_FILE: {mission_file} changed while the run was designed; run it again")
    route = design.turn_points()
    texts = {
        "plan.json": json.dumps(shakedown_plan(design, mission_file, text), indent=1, allow_nan=False) + "\n",
        f"{SCENARIO_ID}.plan": json.dumps(qgc_plan(m, design.u, route), indent=4, allow_nan=False) + "\n",
        f"{SCENARIO_ID}.waypoints": wpl(m, design.u, route),
        f"{SCENARIO_ID}.geojson": json.dumps(_picture(design), indent=1, allow_nan=False) + "\n",
    }
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    for name, body in texts.items():
        tmp = out / f".{name}.tmp"
        tmp.write_text(body, encoding="utf-8")
        os.replace(tmp, out / name)
    return out / "plan.json"
