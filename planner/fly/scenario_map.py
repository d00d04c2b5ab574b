"""The scenario's map for the log: its mission elements and the plan's predicted track, on the bus.

The logger (:mod:`bridge.logger`) writes the document of ``rapt/<v>/map/<name>`` as a
``foxglove.GeoJSON`` channel, so Foxglove's Map panel shows the mission areas, no-go areas,
start and recovery points and the predicted track under the vehicle's ``foxglove.LocationFix``.
The bridge cannot build it (it must not import :mod:`sim`); the planner, which flies the
scenario, can: the document is :func:`planner.common.geojson.geojson`'s, the one the range already
gets as a ``.geojson`` file, with the batch simulator's trajectory of the same row.

:class:`ScenarioMap` puts it whenever a logger's liveliness token (``rapt/<v>/alive/logger``)
appears, including one already there when it starts. The logger declares its token after
its subscriber, so each logger records the document once, whichever process starts first
(a standalone ``rapt-plan log`` too); a second logger's arrival sends it again to all.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import zenoh

import sim.uuv
from bridge import keys
from bridge.service import Service
from bridge.session import receive, undeclare
from planner.common.geojson import geojson
from sim.uuv.mission import Mission

__all__ = ["SCENARIO_MAP", "scenario_map", "ScenarioMap"]

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


class ScenarioMap(Service):
    """Scenario ``u``'s map on ``rapt/<vehicle>/map/scenario``, put for each logger that appears until closed."""

    _what = "scenario map"

    def __init__(self, session, vehicle: str, mission: Mission, u):
        super().__init__()
        self.session = session
        self.vehicle = vehicle
        self.key = keys.map_document(vehicle, SCENARIO_MAP)
        self.document = scenario_map(mission, u)
        self._payload = b"" if self.document is None else json.dumps(self.document, allow_nan=False).encode()
        self._loggers: Any = None
        self.puts = 0

    def _open(self) -> None:
        if self.document is None:
            return
        self._loggers = self.session.liveliness().declare_subscriber(
            keys.alive(self.vehicle, "logger"), zenoh.handlers.FifoChannel(16), history=True
        )
        self._spawn("scenario-map", self._serve)

    def _serve(self) -> None:
        """Put the document for each logger token that appears (never from inside a Zenoh callback)."""
        for sample in receive(self._loggers):
            if sample.kind == zenoh.SampleKind.PUT:
                self.session.put(self.key, self._payload)
                self.puts += 1

    def _shutdown(self) -> None:
        undeclare(self._loggers)  # ends _serve's receive()
        self._join(self._threads, timeout=5)
