"""What the bare autopilot needs of the front-seat that hosts it, and the counters they share.

:class:`sim.uuv.ardusub.bare.BareAutopilot` flies the vehicle of a
:class:`sim.uuv.ardusub.frontseat.FrontSeat`: it reads the host's link, world, parameters and
mode, counts into the host's :class:`FrontSeatStats`, and hands every incoming message and
status text to the host.  :class:`Host` names exactly that, so the bare autopilot depends on
this interface and not on the front-seat that implements it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol

from sim.uuv.ardusub.gcs import GroundStationLink
from sim.uuv.ardusub.mission_server import MissionServer
from sim.uuv.ardusub.params import ParameterTable
from sim.uuv.ardusub.streams import StreamSchedule
from sim.uuv.geo import LocalFrame
from sim.uuv.mission import Mission
from sim.uuv.world import World

__all__ = ["FrontSeatStats", "Host"]


@dataclass
class FrontSeatStats:
    ticks: int = 0
    setpoints: int = 0
    ignored: int = 0
    failsafes: int = 0
    ended: str = ""
    ticks_at_end: int = 0
    log: list = field(default_factory=list)
    #: Bare mode: a position report's time_boot_ms -> wall seconds from sending it to the first
    #: set-point stamped with it (what a benchmark calls telemetry in -> set-point out).
    latency_s: dict = field(default_factory=dict)


class Host(Protocol):
    """The front-seat a :class:`sim.uuv.ardusub.bare.BareAutopilot` runs in."""

    conn: Any  # the pymavlink connection
    mission: Mission
    world: World
    frame: LocalFrame
    speedup: float
    params: ParameterTable
    streams: StreamSchedule
    missions: MissionServer
    link: GroundStationLink
    stats: FrontSeatStats
    mode: int
    armed: bool

    def stop_requested(self) -> bool:
        """True once the host was told to stop serving."""
        ...

    def handle(self, msg) -> None:
        """Answer one incoming MAVLink message."""
        ...

    def send_status(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT (and keep it in ``stats.log``)."""
        ...
