"""The referee of a run on a vehicle we do not simulate: the track on the scenario clock, and when the run ends.

Our simulated front-seat referees its own runs; a real vehicle knows nothing of the
scenario's rules.  So the run is refereed from the vehicle's reports: each period
(``mission.dt`` of the vehicle's clock from the scenario clock's start) the first
position report becomes one track row (:data:`sim.uuv.replay.TRACK_FIELDS` plus speed
and yaw rate; :class:`planner.common.telemetry.TrackSampler`), scored as it comes by the
batch scorer (:class:`sim.uuv.replay.TrackScorer`) — recovered, collision, out of the area, battery empty — or the time limit.  The same
sampling turns a logged run back into its track for ``rapt-plan compare``.
"""

from __future__ import annotations

import json
import os

import numpy as np

os.environ.setdefault("MAVLINK20", "1")

from bridge import keys  # noqa: E402
from bridge.service import Service  # noqa: E402
from bridge.session import receive, undeclare  # noqa: E402
from planner.common.telemetry import VIRTUAL_BATTERY_ID, FrameDecoder, TrackSampler, VehicleTelemetry  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.replay import TrackScorer  # noqa: E402

__all__ = ["Referee", "TIME_LIMIT"]

#: The end reason when the mission's time limit passes.
TIME_LIMIT = "time limit"


class Referee(Service):
    """Referee scenario ``u`` from the bus (module docstring); :attr:`ended` is set when the run ends.

    The scenario clock starts at :meth:`begin`.  The end is published on
    ``status/referee`` as ``{"ended": reason, "time_boot_ms": ...}``, which the log keeps.
    """

    _what = "referee"

    def __init__(self, session, vehicle: str, mission: Mission, u, *, battery_id: int = VIRTUAL_BATTERY_ID):
        super().__init__()
        self.mission, self.u = mission, np.asarray(u, dtype=float)
        self.scorer = TrackScorer(mission, self.u)
        self.telemetry = VehicleTelemetry(LocalFrame(mission.origin_lat, mission.origin_lon), battery_id)
        self.sampler: TrackSampler | None = None
        self.ended = ""
        self.ended_ms = -1
        self._decoder = FrameDecoder()
        self._sub = session.declare_subscriber(keys.raw(vehicle))
        self._pub = session.declare_publisher(keys.status(vehicle, "referee"))

    def begin(self, start_ms: int) -> None:
        """Start the scenario clock at the vehicle's ``time_boot_ms`` = ``start_ms``."""
        self.sampler = TrackSampler(self.telemetry, start_ms, int(round(self.mission.dt * 1000)))

    def track(self) -> np.ndarray:
        return self.sampler.track() if self.sampler is not None else np.zeros((0, 8))

    def _open(self) -> None:
        self._spawn("referee", self._run)

    def _shutdown(self) -> None:
        undeclare(self._sub)  # ends the reader's receive()
        self._join(self._threads, timeout=5)
        undeclare(self._pub)

    def _run(self) -> None:
        for sample in receive(self._sub):
            for msg in self._decoder.decode(sample.payload.to_bytes()):
                if self.telemetry.add(msg) == "position" and self.sampler is not None and not self.ended:
                    assert self.telemetry.pose is not None
                    row = self.sampler.add(self.telemetry.pose)
                    if row is not None:
                        self._score(row)

    def _score(self, row: tuple[float, ...]) -> None:
        if self.scorer.add(*row[:6]):
            self._end(self.scorer.ended, row)
        elif row[0] >= self.mission.time_limit_s:
            self._end(TIME_LIMIT, row)

    def end(self, reason: str) -> None:
        """End the run from outside (the watchdog took over, the operator stopped it), unless it already ended."""
        if self.ended:
            return
        rows = self.sampler.rows if self.sampler is not None else []
        row = rows[-1] if rows else (0.0,) * 8
        self._end(reason, row)

    def _end(self, reason: str, row: tuple[float, ...]) -> None:
        start_ms = self.sampler.start_ms if self.sampler is not None else 0
        self.ended_ms = int(round(row[0] * 1000)) + start_ms
        self.ended = reason
        self._pub.put(json.dumps({"ended": reason, "time_boot_ms": self.ended_ms, "t": row[0]}))
