"""Score a run from its telemetry alone: software-in-the-loop logs and range-day logs.

A run flown over MAVLink leaves a track of what the vehicle reported each step — time,
position, heading, energy used, surfaced — plus the autonomy's own account of which
waypoints it abandoned and why it turned home.  Re-scoring that track with the batch
simulator's scorer gives the same score vector as the batch run of the scenario, since
both see the same reported values (:mod:`sim.uuv.interface`).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from rapt.errors import InputError
from sim.uuv.geometry import rect_signed_distance
from sim.uuv.interface import battery_fraction
from sim.uuv.mission import Mission
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import Scorer
from sim.uuv.sonar import sense
from sim.uuv.world import Telemetry

__all__ = ["TRACK_FIELDS", "score_track", "TrackScorer", "TrackBuilder"]

#: Columns of a track: one row per reported step.
TRACK_FIELDS = ("t", "x", "y", "heading", "energy_hj", "surfaced")


def score_track(
    mission: Mission,
    u: np.ndarray | Sequence[float],
    track: np.ndarray,
    wp_aborted: Sequence[bool] = (),
    return_reason: int = 0,
) -> np.ndarray:
    """Score vector of scenario ``u`` (unit cube) from its ``track`` (steps, TRACK_FIELDS).

    Scoring stops where the scorer says the run ended (recovered, collided, out of the
    area, out of battery) or at the end of the track.
    """
    track = np.asarray(track, dtype=float)
    if track.ndim != 2 or track.shape[1] < len(TRACK_FIELDS) or track.shape[0] == 0:
        raise InputError(f"track: expected rows of {', '.join(TRACK_FIELDS)}, got shape {track.shape}")
    scorer = TrackScorer(mission, u)
    for row in track[:, :6]:
        if scorer.add(*row):
            break
    return scorer.scores(wp_aborted, return_reason)


class TrackScorer:
    """The batch scorer fed one reported step at a time: what a live referee and :func:`score_track` share.

    :meth:`add` takes one row of TRACK_FIELDS and returns whether the run ends there;
    :attr:`ended` then names why, in the front-seat's words.
    """

    def __init__(self, mission: Mission, u: np.ndarray | Sequence[float]):
        scen = make_scenarios(mission, np.asarray(u, dtype=float)[None, :])
        if not scen.valid[0]:
            raise InputError(f"u: scenario is invalid ({scen.invalid_reason[0]}); it has no score")
        self.mission, self.scen = mission, scen
        self.scorer = Scorer(scen)
        self.start_wh = scen.battery0 * mission.vehicle.battery_wh
        self.ended = ""
        self._active = np.ones(1, dtype=bool)

    def add(self, t: float, x: float, y: float, heading: float, hj: float, surfaced: float) -> bool:
        """Score one step; True when the run ends here (:attr:`ended` says why)."""
        scen, mission = self.scen, self.mission
        qx, qy, qh = np.array([x]), np.array([y]), np.array([heading])
        contacts = sense(qx, qy, qh, scen.obstacle_edges, scen.barriers, mission.vehicle)
        tel = Telemetry(
            float(t),
            qx,
            qy,
            qx,
            qy,
            qh,
            np.array([hj]),
            battery_fraction(self.start_wh, np.array([hj]), mission.vehicle.battery_wh),
            np.array([surfaced > 0]),
            contacts.x,
            contacts.y,
            contacts.distance,
            contacts.detected,
        )
        nogo = rect_signed_distance(qx, qy, scen.nogo) if scen.nogo.shape[1] else None
        if self.scorer.update_from(tel, self._active, nogo)[0]:
            self.ended = self.scorer.end_reason()
            return True
        return False

    def scores(self, wp_aborted: Sequence[bool] = (), return_reason: int = 0) -> np.ndarray:
        """The score vector so far, with the autonomy's account of aborted waypoints and why it turned home."""
        aborted = np.zeros((1, len(self.mission.waypoints)), dtype=bool)
        aborted[0, : len(wp_aborted)] = np.asarray(wp_aborted, dtype=bool)[: len(self.mission.waypoints)]
        return self.scorer.scores(aborted, np.array([int(return_reason)]))[0]


class TrackBuilder:
    """Turns a vehicle's MAVLink telemetry, in order, into track rows (TRACK_FIELDS).

    A step's reports (LOCAL_POSITION_NED, ATTITUDE, BATTERY_STATUS) are closed by
    SYSTEM_TIME; a step reported twice (a front-seat repeating itself for late joiners)
    counts once.  Feed decoded pymavlink messages with :meth:`add`.
    """

    NEEDED = ("LOCAL_POSITION_NED", "ATTITUDE", "BATTERY_STATUS")

    def __init__(self) -> None:
        self.rows: list[tuple[float, ...]] = []
        self._tick: dict[str, object] = {}  # this step's reports by type, until SYSTEM_TIME closes it
        self._last_ms = -1

    def add(self, msg) -> None:
        kind = msg.get_type()
        if kind in self.NEEDED:
            self._tick[kind] = msg
        elif kind == "SYSTEM_TIME":
            ms = int(msg.time_boot_ms)
            if ms > self._last_ms and all(k in self._tick for k in self.NEEDED):
                lp, att, bat = (self._tick[k] for k in self.NEEDED)
                self.rows.append(self._row(ms, lp, att, bat))
                self._last_ms = ms
            self._tick = {}

    def _row(self, ms: int, lp, att, bat) -> tuple[float, ...]:
        """One step's row (TRACK_FIELDS) from its reports; a subclass may add columns."""
        return (
            ms / 1000.0,
            float(lp.y),
            float(lp.x),
            float(att.yaw),
            float(bat.energy_consumed),
            1.0 if lp.z <= 0 else 0.0,
        )

    def track(self) -> np.ndarray:
        return np.array(self.rows, dtype=float).reshape(-1, len(TRACK_FIELDS))
