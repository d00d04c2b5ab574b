"""ArduSub's AUTO mode on the bare front-seat: fly the uploaded mission item by item.

Measured on ArduSub SITL 4.7.0-dev: entering AUTO (armed) starts the current item, item 1
when the mission is new or complete; a waypoint is reached within WPNAV_RADIUS (2 m) of it,
in three dimensions, then waits its delay (param1 s); a LOITER_TIME holds its point for
param1 s once there.  Items that are not a place to go (DO_*, CONDITION_*) are passed
over.  After the last item the vehicle holds where it is and the mission is COMPLETE.  The
reports (MISSION_ITEM_REACHED, MISSION_CURRENT, the STATUSTEXTs) are
:class:`sim.uuv.ardusub.mission_server.MissionServer`'s.

Not modelled: ArduSub SITL also runs through a mission while disarmed in AUTO (every item
"reached" within seconds though nothing moved); here a disarmed vehicle stays put and its
mission does not advance.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.guided import Target  # noqa: E402
from sim.uuv.ardusub.mission_server import LOCATION_COMMANDS, MissionServer  # noqa: E402

__all__ = ["AutoMission", "WPNAV_RADIUS_M"]

mav = mavutil.mavlink

#: ArduSub's default WPNAV_RADIUS (200 cm): how close a waypoint counts as reached.
WPNAV_RADIUS_M = 2.0


class AutoMission:
    """Turns the mission into GUIDED-style targets; ``north_east(lat, lon)`` is metres from the EKF origin."""

    def __init__(self, missions: MissionServer, north_east: Callable[[float, float], tuple[float, float]]):
        self.missions, self.north_east = missions, north_east
        self._hold_until: float | None = None
        self._pending = False
        self._rest: Target | None = None  # where it holds with no item to fly

    def start(self) -> None:
        """AUTO was entered: start at the next step (after the mode change's COMMAND_ACK, as ArduSub orders them)."""
        self._pending = True

    def begin(self) -> None:
        """Resume the current item, or start again from item 1, if AUTO was just entered."""
        if not self._pending:
            return
        self._pending = False
        self._rest = None
        ms = self.missions
        if len(ms.mission) < 2:
            return
        seq = ms.current
        if ms.state == mav.MISSION_STATE_COMPLETE or not 0 < seq < len(ms.mission):
            seq = 1
        self._hold_until = None
        ms.start_item(self._next_place(seq))

    def target(self, t: float, north: float, east: float, depth: float) -> Target:
        """Where to go now, given where the vehicle is; reports items reached on the way."""
        ms = self.missions
        if ms.state != mav.MISSION_STATE_ACTIVE or not 0 < ms.current < len(ms.mission):
            if self._rest is None:
                self._rest = Target(north=north, east=east, depth=depth, received=t)
            return self._rest
        item = ms.mission[ms.current]
        if item.x == 0 and item.y == 0:  # no place given (RETURN_TO_LAUNCH): home, on the surface
            item = ms.home
        n, e = self.north_east(item.x * 1e-7, item.y * 1e-7)
        d = max(0.0, -item.z)
        here = Target(north=n, east=e, depth=d, received=t)
        if self._hold_until is None:
            if math.dist((n, e, d), (north, east, depth)) > WPNAV_RADIUS_M:
                return here
            self._hold_until = t + max(0.0, item.param1)  # the delay (WP) or loiter time (LOITER_TIME)
        if t < self._hold_until:
            return here
        self._hold_until = None
        seq = ms.current
        ms.reached(seq, self._next_place(seq + 1) if seq + 1 < len(ms.mission) else seq + 1)
        return here

    def _next_place(self, seq: int) -> int:
        """The first item from ``seq`` on that is a place to go (the last item if none is)."""
        mission = self.missions.mission
        while seq < len(mission) - 1 and mission[seq].command not in LOCATION_COMMANDS:
            seq += 1
        return seq
