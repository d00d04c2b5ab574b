"""The scenario record of a flown run (``rapt/<v>/meta/scenario``): written when flying, read when reviewing.

A run's log must say which scenario was flown, or ``rapt-plan compare`` has nothing to
predict it with: the mission (its name and file), the plan and scenario ids, the scenario's
unit-cube row ``u`` and its decoded parameters.  A run on a vehicle we do not simulate adds
how it was flown: the vehicle's link, ``"pacing": "vehicle"`` (the track is sampled on the
vehicle's clock, :class:`planner.common.telemetry.TrackSampler`), the mission's origin and
its period ``dt``.  The logger keeps the record twice: as the ``meta/scenario`` message and
as the MCAP metadata record ``scenario`` (:mod:`bridge.logger`), whose values are text.

:func:`scenario_json` writes it (the SIL loop and the vehicle run); :func:`metadata_fields` and
:func:`paced_clock` read it back (:mod:`planner.review.logs`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from planner.common.jsonio import jsonable
from sim.uuv.legs import Leg, leg_records
from sim.uuv.mission import Mission

__all__ = ["SCENARIO_META", "scenario_json", "metadata_fields", "PacedClock", "paced_clock"]

#: The record's name: ``rapt/<v>/meta/scenario`` on the bus, the ``scenario`` metadata record in the log.
SCENARIO_META = "scenario"
#: The fields whose metadata-record text is JSON (the rest are plain text).
_JSON_FIELDS = ("u", "parameters", "legs")
#: The period of a vehicle-paced record without ``dt`` (s).
_DEFAULT_DT = 2.0


def scenario_json(
    mission: Mission,
    u,
    *,
    mission_file: str = "",
    scenario_id: str = "",
    plan_id: str = "",
    vehicle_link: str | None = None,
    legs: tuple[Leg, ...] = (),
) -> str:
    """The record of scenario ``u`` of ``mission`` as JSON text; ``mission_file`` defaults to ``mission.source``.

    ``vehicle_link`` (the pymavlink connection string of a vehicle we do not simulate) adds the
    vehicle-paced fields: the link, the pacing, the mission's origin and period.  ``legs`` (a calibration
    run's) add ``"calibration": "shakedown"`` and each leg with its scheduled start and end
    (:func:`sim.uuv.legs.leg_records`), which the calibration fit reads.
    """
    row = np.asarray(u, dtype=float)
    record = {
        "mission": mission.name,
        "mission_file": mission_file or mission.source,
        "scenario_id": scenario_id,
        "plan_id": plan_id,
        "u": row.tolist(),
        "parameters": jsonable(mission.space.decode(row[None, :])[0]),
    }
    if legs:
        record |= {"calibration": "shakedown", "legs": leg_records(legs)}
    if vehicle_link is not None:
        record |= {
            "vehicle_link": vehicle_link,
            "pacing": "vehicle",
            "origin": [mission.origin_lat, mission.origin_lon],
            "dt": mission.dt,
        }
    return json.dumps(record)


def metadata_fields(metadata: Mapping[str, str]) -> dict:
    """The record's fields from its MCAP metadata record (text values; ``u`` and ``parameters`` JSON)."""
    fields: dict = {}
    for k, v in metadata.items():
        try:
            fields[k] = json.loads(v) if k in _JSON_FIELDS else v
        except ValueError:
            fields[k] = v
    return fields


@dataclass(frozen=True)
class PacedClock:
    """How a vehicle-paced run's track is sampled: the mission's origin and period."""

    origin_lat: float
    origin_lon: float
    dt: float


def paced_clock(record: Mapping) -> PacedClock | None:
    """The sampling of a vehicle-paced run's record; None for a lock-step run (or no usable origin)."""
    origin = record.get("origin")
    if record.get("pacing") != "vehicle" or not isinstance(origin, list) or len(origin) != 2:
        return None
    return PacedClock(float(origin[0]), float(origin[1]), float(record.get("dt", _DEFAULT_DT)))
