"""A real vehicle's telemetry as it arrives: the latest report of each kind, by the vehicle's clock.

A vehicle we do not simulate streams at its own rates, reports its position in latitude
and longitude (its ``LOCAL_POSITION_NED`` is relative to wherever its estimator started,
not to the range's origin), and the network may deliver a report late, twice or out of
order.  Everything on our side that follows such a vehicle — the back-seat, the virtual
range elements, the watchdog, the run's referee — reads it through
:class:`VehicleTelemetry`: it keeps the newest report of each kind with the vehicle's
``time_boot_ms``, drops (and counts) reports older than one already seen, and gives the
pose in the mission's local frame (x east, y north) through :class:`sim.uuv.geo.LocalFrame`.
:class:`TrackSampler` turns those poses into a track on the scenario clock, for the referee
of a live run and for the review of its log alike.
"""

from __future__ import annotations

import math
import os
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from bridge.frames import message_id
from sim.uuv.geo import LocalFrame

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

__all__ = [
    "Pose",
    "Contact",
    "VehicleTelemetry",
    "TrackSampler",
    "FrameDecoder",
    "KINDS",
    "VIRTUAL_BATTERY_ID",
    "SURFACED_DEPTH_M",
    "SurfaceDetector",
]

#: The messages :class:`VehicleTelemetry` reads; anything else on the stream is skipped undecoded.
KINDS = (
    "HEARTBEAT",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "BATTERY_STATUS",
    "OBSTACLE_DISTANCE_3D",
    "EKF_STATUS_REPORT",
    "GPS_RAW_INT",
)

#: BATTERY_STATUS.id of the virtual fuel gauge (the scenario's charge; the pack itself is id 0).
VIRTUAL_BATTERY_ID = 99
#: A vehicle this close to the surface counts as surfaced (a real depth reading hovers around 0).
SURFACED_DEPTH_M = 0.3
#: A vehicle shallower than this whose depth has stopped rising counts as surfaced too: a depth
#: sensor sits below the waterline (ArduSub SITL floats at 0.36 m under a surface command, a
#: BlueROV2's sensor a few decimetres down), so the reading at the top is the vehicle's own,
#: not 0.  Half the running depth (:data:`sim.uuv.interface.DEPTH_M`), where nothing holds but
#: a vehicle at the surface.
SURFACE_BAND_M = 1.0
#: "Stopped rising": the depth reports over the last this many vehicle milliseconds span at
#: most :data:`SETTLED_SPAN_M` (a rise at 0.5 m/s moves 1.5 m in that time; a turnaround at
#: the top of an ascent or the start of a dive passes in well under it).
SETTLED_MS = 3000
SETTLED_SPAN_M = 0.05
#: GLOBAL_POSITION_INT.hdg when the heading is unknown.
_NO_HDG = 65535


class FrameDecoder:
    """Decodes the wanted messages of the bus's raw stream and skips the rest by the id in their header.

    A real vehicle streams dozens of message types; every reader on the bus (back-seat,
    virtual range, watchdog, referee) needs a few, and decoding all of them in each reader is
    what would make set-points late at a high simulator speed-up.  Samples hold one frame
    each (the bridge publishes them so); anything else is parsed in full.
    """

    def __init__(self, kinds=KINDS):
        self.ids = frozenset(getattr(mavlink, f"MAVLINK_MSG_ID_{k}") for k in kinds)
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.skipped = 0

    def decode(self, payload: bytes) -> list:
        msg_id = message_id(payload)
        if msg_id is not None and msg_id not in self.ids:
            self.skipped += 1
            return []
        return self.parser.parse_buffer(payload) or []


@dataclass(frozen=True)
class Pose:
    """Where the vehicle reported itself at ``time_ms`` (its ``time_boot_ms``), in the mission frame."""

    time_ms: int
    east: float
    north: float
    depth: float  # metres below the surface
    heading: float  # compass radians, from ATTITUDE.yaw (or GLOBAL_POSITION_INT.hdg before the first ATTITUDE)
    heading_ms: int
    speed: float = 0.0  # over ground, m/s (GLOBAL_POSITION_INT vx, vy)
    yaw_rate: float = 0.0  # rad/s (ATTITUDE.yawspeed)
    settled_at_top: bool = False  # shallower than SURFACE_BAND_M and stopped rising (SurfaceDetector)

    @property
    def surfaced(self) -> bool:
        """Near 0 m, or at the top of an ascent where the vehicle's own depth sensor reads more."""
        return self.depth <= SURFACED_DEPTH_M or self.settled_at_top


class SurfaceDetector:
    """Whether a vehicle's depth reports say it has stopped rising within :data:`SURFACE_BAND_M`.

    Fed every position report in vehicle-time order; true once the reports of the last
    :data:`SETTLED_MS` (and at least that long a history inside the band) span at most
    :data:`SETTLED_SPAN_M`.  Stateful because one report cannot tell a vehicle floating at
    0.36 m from one passing 0.36 m on its way up or down.
    """

    def __init__(self) -> None:
        self._band: deque[tuple[int, float]] = deque()

    def add(self, time_ms: int, depth: float) -> bool:
        if not depth < SURFACE_BAND_M:
            self._band.clear()
            return False
        band = self._band
        if band and time_ms < band[-1][0]:  # a clock that went back: the vehicle rebooted
            band.clear()
        band.append((time_ms, depth))
        while len(band) > 1 and band[1][0] <= time_ms - SETTLED_MS:
            band.popleft()
        if time_ms - band[0][0] < SETTLED_MS:
            return False
        depths = [d for _, d in band]
        return max(depths) - min(depths) <= SETTLED_SPAN_M


@dataclass(frozen=True)
class Contact:
    """One sonar contact (OBSTACLE_DISTANCE_3D) in the mission frame, as of ``time_ms``."""

    time_ms: int
    east: float
    north: float


@dataclass
class TelemetryCounts:
    """What arrived and what was dropped, for the run's account."""

    messages: int = 0
    positions: int = 0
    out_of_order: int = 0  # older than a report of the same kind already seen: dropped
    duplicates: int = 0  # the same report again (same kind, same time_boot_ms)
    reboots: int = 0  # the vehicle's clock went back by more than REBOOT_JUMP_MS


@dataclass
class VehicleTelemetry:
    """Latest reports of one vehicle (see the module docstring); feed decoded pymavlink messages to :meth:`add`.

    ``battery_id`` selects the BATTERY_STATUS the run counts on: the pack (0) or the
    virtual fuel gauge (:data:`VIRTUAL_BATTERY_ID`).
    """

    frame: LocalFrame
    battery_id: int = 0
    counts: TelemetryCounts = field(default_factory=TelemetryCounts)

    REBOOT_JUMP_MS = 10_000
    #: Poses kept to place a body-frame contact relative to the pose it was measured from.
    POSE_HISTORY = 32

    def __post_init__(self) -> None:
        self.now_ms = -1  # the newest vehicle time seen
        self._last: dict[str, int] = {}  # newest time_boot_ms per kind
        self._yaw: tuple[int, float, float] | None = None
        self.pose: Pose | None = None
        self._surface = SurfaceDetector()
        self._poses: deque[Pose] = deque(maxlen=self.POSE_HISTORY)
        self.energy_hj: int | None = None  # of the selected battery
        self.energy_ms = -1  # vehicle time when it arrived
        self.pack = None  # the pack's own BATTERY_STATUS (id 0)
        self.contacts: dict[int, Contact] = {}
        self.heartbeat = None
        self.ekf = None
        self.gps_fix = 0

    # -- input -------------------------------------------------------------------------
    def add(self, msg) -> str | None:
        """Take one decoded message; returns ``"position"`` when it brought a new pose, else None."""
        kind = msg.get_type()
        self.counts.messages += 1
        boot_ms = getattr(msg, "time_boot_ms", None)
        stamp = self.now_ms if boot_ms is None else int(boot_ms)
        if boot_ms is not None and kind != "SET_POSITION_TARGET_LOCAL_NED":
            key = f"{kind}:{msg.obstacle_id}" if kind == "OBSTACLE_DISTANCE_3D" else kind
            if not self._fresh(key, stamp):
                return None
        if kind == "GLOBAL_POSITION_INT":
            return self._position(msg, stamp)
        if kind == "ATTITUDE":
            self._yaw = (stamp, float(msg.yaw), float(msg.yawspeed))
        elif kind == "BATTERY_STATUS":
            self._battery(msg)
        elif kind == "OBSTACLE_DISTANCE_3D":
            self._contact(msg, stamp)
        elif kind == "HEARTBEAT":
            if msg.autopilot != 8:  # MAV_AUTOPILOT_INVALID: a companion, not the vehicle
                self.heartbeat = msg
        elif kind == "EKF_STATUS_REPORT":
            self.ekf = msg
        elif kind == "GPS_RAW_INT":
            self.gps_fix = int(msg.fix_type)
        return None

    def _fresh(self, kind: str, stamp: int) -> bool:
        last = self._last.get(kind, -1)
        if stamp == last:
            self.counts.duplicates += 1
            return False
        if stamp < last:
            if last - stamp > self.REBOOT_JUMP_MS and stamp < self.REBOOT_JUMP_MS:
                self.counts.reboots += 1  # the vehicle rebooted: start over with its new clock
                self._last.clear()
                self._poses.clear()
                self.now_ms = -1
            else:
                self.counts.out_of_order += 1
                return False
        self._last[kind] = stamp
        self.now_ms = max(self.now_ms, stamp)
        return True

    def _position(self, msg, stamp: int) -> str | None:
        if msg.lat == 0 and msg.lon == 0:
            return None  # no position estimate yet (ArduSub reports 0, 0 until it has an origin)
        east, north = self.frame.to_local(msg.lat * 1e-7, msg.lon * 1e-7)
        yaw_rate = 0.0
        if self._yaw is not None:
            heading_ms, heading, yaw_rate = self._yaw
        elif msg.hdg != _NO_HDG:
            heading_ms, heading = stamp, _wrap(math.radians(msg.hdg / 100.0))
        else:
            heading_ms, heading = stamp, 0.0
        speed = math.hypot(msg.vx, msg.vy) / 100.0
        depth = -msg.relative_alt / 1000.0
        top = self._surface.add(stamp, depth)
        self.pose = Pose(stamp, float(east), float(north), depth, heading, heading_ms, speed, yaw_rate, top)
        self._poses.append(self.pose)
        self.counts.positions += 1
        return "position"

    def _battery(self, msg) -> None:
        if int(msg.id) == 0:
            self.pack = msg
        if int(msg.id) != self.battery_id:
            return
        energy = int(msg.energy_consumed)
        if energy < 0:  # not reported: count it from the charge drawn and the pack voltage
            mah, mv = int(msg.current_consumed), int(msg.voltages[0])
            if mah < 0 or mv in (0, 65535):
                return
            energy = int(mah * mv / 1e6 * 36.0)
        self.energy_hj, self.energy_ms = energy, self.now_ms

    def _contact(self, msg, stamp: int) -> None:
        # a sensor stamps a body-frame contact with its pose's time: a newer pose may have arrived since
        pose = next((p for p in reversed(self._poses) if p.time_ms == stamp), self.pose)
        if msg.frame == 12 and pose is not None:  # MAV_FRAME_BODY_FRD: x forward, y right, from the sensor's pose
            s, c = math.sin(pose.heading), math.cos(pose.heading)
            east = pose.east + msg.x * s + msg.y * c
            north = pose.north + msg.x * c - msg.y * s
        elif msg.frame == 1:  # MAV_FRAME_LOCAL_NED, taken as the mission frame
            east, north = float(msg.y), float(msg.x)
        else:
            return
        self.contacts[int(msg.obstacle_id)] = Contact(stamp, float(east), float(north))

    # -- queries ---------------------------------------------------------------------------
    def recent_contacts(self, since_ms: int) -> dict[int, Contact]:
        """Contacts reported at or after ``since_ms`` (older ones are out of sight now)."""
        return {j: c for j, c in self.contacts.items() if c.time_ms >= since_ms}


class TrackSampler:
    """One row per period of the vehicle's clock from ``start_ms``: t, x, y, heading, energy, surfaced, speed, yaw rate."""

    def __init__(self, telemetry: VehicleTelemetry, start_ms: int, period_ms: int):
        self.telemetry, self.start_ms, self.period_ms = telemetry, int(start_ms), int(period_ms)
        self.next_ms = self.start_ms
        self.rows: list[tuple[float, ...]] = []

    def add(self, pose: Pose) -> tuple[float, ...] | None:
        """The row this report opens, or None (not yet the next period, or no battery reading yet)."""
        energy = self.telemetry.energy_hj
        if pose.time_ms < self.next_ms or energy is None:
            return None
        self.next_ms += ((pose.time_ms - self.next_ms) // self.period_ms + 1) * self.period_ms
        row = (
            (pose.time_ms - self.start_ms) / 1000.0,
            pose.east,
            pose.north,
            pose.heading,
            float(energy),
            1.0 if pose.surfaced else 0.0,
            pose.speed,
            pose.yaw_rate,
        )
        self.rows.append(row)
        return row

    def track(self) -> np.ndarray:
        return np.array(self.rows, dtype=float).reshape(-1, 8)


def _wrap(a: float) -> float:
    """Compass radians into (-pi, pi], as ATTITUDE.yaw reports them."""
    return math.atan2(math.sin(a), math.cos(a))
