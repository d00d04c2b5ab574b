"""The scenario's map for the log: its mission elements and the plan's predicted track, put once on the bus.

The logger (:mod:`bridge.logger`) writes the document of ``rapt/<v>/map/<name>`` as a
``foxglove.GeoJSON`` channel, so Foxglove's Map panel shows the mission areas, no-go areas,
start and recovery points and the predicted track under the vehicle's ``foxglove.LocationFix``.
The bridge cannot build it (it must not import :mod:`sim`); the planner, which flies the
scenario, can: the document is :func:`planner.exports.geojson`'s, the one the range already
gets as a ``.geojson`` file, with the batch simulator's trajectory of the same row.
"""

from __future__ import annotations

import json

import numpy as np

import sim.uuv
from bridge import keys
from planner.exports import geojson
from sim.uuv.mission import Mission

__all__ = ["SCENARIO_MAP", "scenario_map", "publish_scenario_map"]

#: The map document's name on the bus (``rapt/<v>/map/scenario``) and in the log (``/map/scenario``).
SCENARIO_MAP = "scenario"


def scenario_map(mission: Mission, u) -> dict | None:
    """Scenario ``u``'s GeoJSON FeatureCollection with its predicted track; None for an invalid scenario
    (it has no elements to draw; the run says why it is invalid)."""
    row = np.asarray(u, dtype=float)
    predicted = sim.uuv.simulate(mission, row[None, :], trajectories=True)
    if not predicted.valid[0]:
        return None
    return geojson(mission, row, predicted.trajectory(0))


def publish_scenario_map(session, vehicle: str, mission: Mission, u) -> dict | None:
    """Put scenario ``u``'s map on ``rapt/<vehicle>/map/scenario`` (once: a logger already listening records it)."""
    document = scenario_map(mission, u)
    if document is not None:
        session.put(keys.map_document(vehicle, SCENARIO_MAP), json.dumps(document, allow_nan=False))
    return document
