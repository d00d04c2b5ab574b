"""Names and kinds of a mission's score columns (the vocabulary of its score tree).

The scorer (:mod:`sim.uuv.scoring`) returns one column per name, in this order; mission
files build their score tree from these names (:mod:`sim.uuv.missionfile`), with ``{name}``
standing for each element of a kind.  The layout follows Figure 4.11: mission and safety
success at the root, then one pass/fail node per objective or rule, then one per
element, and continuous leaf metrics (closest approach, times, dwell, battery) below.

Pass/fail columns are 1.0 for pass.  Times are seconds since the mission start; a time
that never happened is reported as the mission's time limit, a distance that was never
measured as 10 km, so every score is finite.
"""

from __future__ import annotations

from rapt.errors import InputError
from sim.uuv.mission import Mission

__all__ = ["metric_names", "metric_types", "ELEMENT_KINDS", "element_names", "NEVER_M"]

#: The stand-in for "never came within sonar/measurement range".
NEVER_M = 10_000.0

#: ``for_each`` kinds a score-tree node may be replicated over.
ELEMENT_KINDS = ("waypoint", "area", "obstacle", "barrier", "nogo")

ROOT = ("mission_success", "safety_success")
MISSION_NODES = ("waypoints", "mission_areas", "transmission", "mission_time")
SAFETY_NODES = ("collisions", "nogo_areas", "operational_area", "recovery", "surfacing")

WAYPOINT_LEAVES = ("closest_m", "time_s", "battery", "aborted")
AREA_LEAVES = ("dwell_s", "entry_s", "done_s", "closest_m", "order")
TRANSMISSION_LEAVES = ("time_s", "window_margin_s", "closest_m", "surface_s")
MISSION_LEAVES = ("time_s", "battery_left", "distance_m", "return_reason")
OBSTACLE_LEAVES = ("closest_m", "time_s", "detected_s")
NOGO_LEAVES = ("closest_m", "inside_s", "time_s")
OPERATIONAL_LEAVES = ("margin_m",)
RECOVERY_LEAVES = ("distance_m", "time_s", "battery")
SURFACING_LEAVES = ("outside_s", "count")

#: Leaves that are categorical rather than continuous.
_CATEGORICAL_LEAVES = {
    "aborted": "binary",
    "order": "categorical",
    "return_reason": "categorical",
    "count": "categorical",
}


def element_names(mission: Mission, kind: str) -> list[str]:
    """Names of the elements of ``kind`` (waypoints are numbered from 0)."""
    if kind == "waypoint":
        return [str(i) for i in range(len(mission.waypoints))]
    if kind == "area":
        return [a.name for a in mission.mission_areas]
    if kind == "obstacle":
        return [o.name for o in mission.obstacles]
    if kind == "barrier":
        return [b.name for b in mission.barriers]
    if kind == "nogo":
        return [z.name for z in mission.nogo]
    raise InputError(f"kind: expected one of {', '.join(ELEMENT_KINDS)}, got {kind!r}")


def metric_names(mission: Mission) -> list[str]:
    """Every score column of ``mission``, in the order the scorer returns them."""
    names = list(ROOT) + [n for n in MISSION_NODES if n != "transmission" or mission.transmission is not None]
    names += list(SAFETY_NODES)
    for kind in ELEMENT_KINDS:
        names += [f"{kind}.{e}" for e in element_names(mission, kind)]
    names += [f"waypoint.{e}.{leaf}" for e in element_names(mission, "waypoint") for leaf in WAYPOINT_LEAVES]
    names += [f"area.{e}.{leaf}" for e in element_names(mission, "area") for leaf in AREA_LEAVES]
    if mission.transmission is not None:
        names += [f"transmission.{leaf}" for leaf in TRANSMISSION_LEAVES]
    names += [f"mission.{leaf}" for leaf in MISSION_LEAVES]
    for kind in ("obstacle", "barrier"):
        names += [f"{kind}.{e}.{leaf}" for e in element_names(mission, kind) for leaf in OBSTACLE_LEAVES]
    names += [f"nogo.{e}.{leaf}" for e in element_names(mission, "nogo") for leaf in NOGO_LEAVES]
    names += [f"operational_area.{leaf}" for leaf in OPERATIONAL_LEAVES]
    names += [f"recovery.{leaf}" for leaf in RECOVERY_LEAVES]
    names += [f"surfacing.{leaf}" for leaf in SURFACING_LEAVES]
    return names


def metric_types(mission: Mission) -> list[str]:
    """rapt output type of each column: pass/fail nodes are binary, leaves mostly continuous."""
    out = []
    for name in metric_names(mission):
        parts = name.split(".")
        if len(parts) <= 2 and not (
            len(parts) == 2 and parts[0] in ("transmission", "mission", "operational_area", "recovery", "surfacing")
        ):
            out.append("binary")
        else:
            out.append(_CATEGORICAL_LEAVES.get(parts[-1], "continuous"))
    return out
