"""What to fly: one scenario of a mission or of a field plan, and where it came from.

Both ways of flying it take a :class:`Flight`: in the loop (:mod:`planner.fly.sil`) and on a
vehicle's MAVLink port (:mod:`planner.fly.vehicle`); where it came from goes into the log.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim.uuv.legs import Leg, legs_from_json
from sim.uuv.mission import Mission

__all__ = ["Flight", "is_plan", "flight_from_plan"]


@dataclass(frozen=True)
class Flight:
    """What to fly: one scenario of a mission, and where it came from (both go into the log).

    ``legs`` (a calibration run's, :mod:`sim.uuv.legs`) are flown in place of the mission's autonomy;
    ``route`` is where its legs begin on the predicted track, then the recovery point (x, y m), which
    bring-up uploads as the vehicle's mission in place of the mission's waypoints."""

    mission: Mission
    u: np.ndarray  # the scenario's unit-cube row
    scenario_id: str
    mission_file: str
    plan_id: str = ""
    legs: tuple[Leg, ...] = ()
    route: tuple[tuple[float, float], ...] = ()


def is_plan(path: Path) -> bool:
    """A field plan (its plan.json or its directory) rather than a mission file."""
    return path.suffix == ".json" or path.is_dir()


def flight_from_plan(path: Path, scenario_id: str | None) -> Flight:
    """Scenario ``scenario_id`` (e.g. pair1a) of the plan at ``path``; ValueError names what is wrong
    (a plan has no default scenario: ``None`` is answered with its ids)."""
    from planner.common.plans import load_plan

    plan = load_plan(path)
    scenario = plan.scenario(scenario_id)
    mission, u = plan.mission, plan.u(scenario["id"])
    legs = legs_from_json(scenario["legs"]) if "legs" in scenario else ()
    route = _leg_route(scenario, mission) if legs else ()
    return Flight(mission, u, scenario["id"], str(plan.mission_file), plan.id, legs, route)


def _leg_route(scenario: dict, mission: Mission) -> tuple[tuple[float, float], ...]:
    """Where each leg begins on the scenario's predicted track, then the recovery point."""
    track = scenario.get("predicted", {}).get("track", {})
    fields, rows = track.get("fields", []), np.asarray(track.get("rows", []), dtype=float)
    if rows.ndim != 2 or rows.shape[0] == 0 or not {"t", "x", "y"} <= set(fields):
        return ()
    t, x, y = (rows[:, fields.index(k)] for k in ("t", "x", "y"))
    starts = [float(leg["start_s"]) for leg in scenario["legs"]]
    points = [(float(np.interp(s, t, x)), float(np.interp(s, t, y))) for s in starts]
    return (*points, (float(mission.recovery[0]), float(mission.recovery[1])))
