"""What the vehicle cannot do: modes and mission elements that no run of the study reaches, and why.

A calibrated vehicle with a smaller pack, or a slower one, may never finish the mission:
then the study holds no TS or MS run, and every pair the plan can offer is an abort or
safety sub-boundary. A range must hear that before it plans its day around a boundary that
does not exist. :func:`unreached` lists what no valid run reached and gives the reason it can
measure from the mission file alone: the best starting charge against the energy the route
needs at cruise (with the autonomy's return reserve), and the route's time against the limit.
"""

from __future__ import annotations

import math

import numpy as np

from rapt.space import Continuous
from sim.uuv.mission import Mission
from sim.uuv.scoring import MODE_NAMES

__all__ = ["no_boundary", "unreached", "unreached_line", "route_length_m"]


def route_length_m(mission: Mission) -> float:
    """The mission's shortest route in still water: launch, waypoints, survey areas' centres, recovery, in order."""
    points = [mission.launch, *mission.waypoints, *((a.x, a.y) for a in mission.mission_areas), mission.recovery]
    return float(sum(math.dist(p, q) for p, q in zip(points, points[1:])))


def _reached_speed(mission: Mission) -> float:
    v = mission.vehicle
    cmd = min(v.cruise_speed, v.max_speed)
    if v.speed_curve:
        knots = [(0.0, 0.0), *v.speed_curve]
        return float(np.interp(cmd, [k[0] for k in knots], [k[1] for k in knots]))
    return float(v.speed_gain * cmd)


def _best_charge(mission: Mission) -> float:
    """The highest starting charge (share of the pack) a scenario of the study can have."""
    for binding in mission.bindings:
        if binding.field == "start_battery":
            param = next(p for p in mission.space.parameters if p.name == binding.parameter)
            if isinstance(param, Continuous):
                return float(param.high)
    return float(mission.vehicle.start_battery)


def _reason(mission: Mission) -> str:
    v = mission.vehicle
    length = route_length_m(mission)
    speed = _reached_speed(mission)
    if speed <= 0:
        return f"the vehicle reaches no speed at its cruise command ({v.cruise_speed:g} m/s)"
    hours = length / speed / 3600.0
    power = v.drag_w * (speed / v.cruise_speed) ** v.power_exponent + v.hotel_w
    need = power * hours * v.reserve_factor
    have = v.battery_wh * _best_charge(mission)
    dwell = sum(a.dwell_s for a in mission.mission_areas)
    parts = []
    if need > have:
        parts.append(
            f"the pack's best start ({have:,.0f} Wh) is under the {need:,.0f} Wh the {length / 1000:.1f} km route "
            f"needs at {speed:.2f} m/s with the {v.reserve_factor:g}x return reserve, before any loiter"
        )
    if hours * 3600 + dwell > mission.time_limit_s:
        parts.append(
            f"the route and its loiters take {(hours * 3600 + dwell) / 60:.0f} min at {speed:.2f} m/s, "
            f"over the {mission.time_limit_s / 60:.0f} min limit"
        )
    if not parts:
        return f"the pack ({have:,.0f} Wh at best) covers the {length / 1000:.1f} km route in still water: the current, no-go areas or timing stop it"
    return "; ".join(parts)


def unreached(mission: Mission, scores: np.ndarray, modes: np.ndarray, names: list[str], types) -> dict:
    """``study.unreached``: the modes and discrete score elements no valid run reached (a 1 on a pass/fail element)
    and, when anything is unreached, the reason measured from the mission (otherwise an empty reason)."""
    seen = set(np.unique(modes[modes >= 0]).tolist())
    missing_modes = [name for m, name in enumerate(MODE_NAMES) if m not in seen]
    elements = []
    if len(scores):
        for c, (name, t) in enumerate(zip(names, types)):
            if t != "continuous" and not np.any(scores[:, c] == 1):
                elements.append(name)
    out = {"modes": missing_modes, "elements": elements, "reason": ""}
    if missing_modes or elements:
        out["reason"] = _reason(mission)
    return out


def unreached_line(record: dict | None) -> str | None:
    """The summary's one line on what the vehicle cannot do (None when every mode and element is reached)."""
    if not record or not (record.get("modes") or record.get("elements")):
        return None
    what = []
    if record.get("modes"):
        what.append(f"no run reaches {', '.join(record['modes'])}")
    if record.get("elements"):
        shown = record["elements"][:6]
        more = len(record["elements"]) - len(shown)
        what.append(f"none passes {', '.join(shown)}" + (f" (+{more} more)" if more > 0 else ""))
    return f"unreached: {'; '.join(what)}: {record.get('reason', '')}"


def no_boundary(mission: Mission, modes: np.ndarray, written_away: int = 0) -> str:
    """The one line refusing a plan with no boundary pair: what the study's valid runs show, and what to change.

    ``written_away``: candidate pairs there were, whose sides all showed one outcome once written at
    the range's resolution (0: the study offered no candidate at all).
    """
    counts = {MODE_NAMES[m]: int(n) for m, n in zip(*np.unique(modes[modes >= 0], return_counts=True))}
    shown = ", ".join(f"{name} {n:,}" for name, n in counts.items()) or "none"
    if written_away:
        why = (
            f"each of the {written_away} candidate pairs shows one outcome on both sides once written at the "
            f"range's resolution; give the parameters a finer resolution or raise --budget for sharper pairs"
        )
    else:
        why = "no two neighbouring runs differ on a scored element; widen the parameters' ranges or raise --budget"
    return (
        f"MISSION_FILE: no boundary to plan in {mission.name} (valid runs by mode: {shown}): {why}; "
        "no plan was written (the study stays in the --out directory for --resume)"
    )
