"""ArduSub's GUIDED set-points, read as ArduSub reads them, and turned into what our vehicle can do.

A client talks to a real vehicle in SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT, whose
type mask and frame decide what is meant; ArduSub obeys a few combinations and drops
the rest without an answer (Sub's GCS_Mavlink.cpp): position, velocity, or position and
velocity, each with or without yaw, acceleration ignored.  Frames LOCAL_NED (relative
to the EKF origin), LOCAL_OFFSET_NED (relative to the vehicle), BODY_NED,
BODY_OFFSET_NED and BODY_FRD (relative to the vehicle and rotated by its heading); for
_GLOBAL_INT the frames whose altitude is relative to home or to the sea surface (home is
on the surface here).  Velocity and position-velocity targets are zeroed 3 s after the
last one (GUIDED_POSVEL_TIMEOUT_MS); a position target is held until replaced.

Measured on ArduSub SITL: 1 m/s north (mask 3527) for 10 s reached 0.73 m/s, and 3 s after
the last set-point the speed fell to 0.2 m/s; mask 0 (acceleration used) and frame 0
(GLOBAL, in the LOCAL message) changed nothing; frames 7, 8, 9 and 12 were obeyed.

Our vehicle is a torpedo (:mod:`sim.uuv.vehicle`): it takes a heading and a through-water
speed and cannot crab or hover.  A horizontal velocity becomes heading ``atan2(vy, vx)``
and speed ``hypot(vx, vy)``; a position becomes a velocity toward it (cruise speed at
most, slowing within ``POSITION_TIME_S`` of it, stopping within ``ARRIVED_M``); a yaw
turns the vehicle only when it is not asked to move (it always points where it goes).
Vertical targets drive :class:`sim.uuv.ardusub.depth.Depth`.  Stopped ("hold") means speed 0 and the
depth kept; the current still carries the vehicle, as it would an ROV with its
horizontal thrusters off.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

__all__ = ["Target", "from_local_ned", "from_global_int", "TIMEOUT_S"]

mav = mavutil.mavlink

#: ArduSub zeroes a velocity or position-velocity target not refreshed within this (GUIDED_POSVEL_TIMEOUT_MS).
TIMEOUT_S = 3.0
#: A position target is approached at (distance / this) m/s, at most the cruise speed.
POSITION_TIME_S = 5.0
#: Closer than this (m) to a position target the vehicle stops.
ARRIVED_M = 1.0

POS_IGNORE, VEL_IGNORE, ACC_IGNORE = 0x7, 0x38, 0x1C0
YAW_IGNORE = 0x400
LOCAL_FRAMES = frozenset(
    {
        mav.MAV_FRAME_LOCAL_NED,
        mav.MAV_FRAME_LOCAL_OFFSET_NED,
        mav.MAV_FRAME_BODY_NED,
        mav.MAV_FRAME_BODY_OFFSET_NED,
        mav.MAV_FRAME_BODY_FRD,
    }
)
BODY_FRAMES = frozenset({mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED, mav.MAV_FRAME_BODY_FRD})
GLOBAL_FRAMES = frozenset(
    {
        mav.MAV_FRAME_GLOBAL,
        mav.MAV_FRAME_GLOBAL_INT,
        mav.MAV_FRAME_GLOBAL_RELATIVE_ALT,
        mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    }
)


@dataclass(frozen=True)
class Target:
    """What GUIDED flies to.  Positions are metres north/east of the EKF origin and depth
    (m, + down); velocities NED m/s; ``yaw`` compass radians or None; ``received`` vehicle s."""

    north: float | None = None
    east: float | None = None
    depth: float | None = None
    vn: float = 0.0
    ve: float = 0.0
    vz: float = 0.0
    yaw: float | None = None
    velocity: bool = False
    received: float = 0.0

    @classmethod
    def hold(cls, depth: float, t: float) -> Target:
        """Stopped where it is, keeping this depth."""
        return cls(depth=depth, received=t)

    def expired(self, t: float) -> bool:
        return self.velocity and t - self.received > TIMEOUT_S

    def timed_out(self, depth: float) -> Target:
        """ArduSub's timeout: the velocity is zeroed; a position (if any) is kept."""
        if self.north is None:
            return Target.hold(depth, self.received)
        return replace(self, vn=0.0, ve=0.0, vz=0.0, velocity=False)

    def advanced(self, dt: float) -> Target:
        """A position-velocity target's position moves on with its velocity (ArduSub's posvel)."""
        if not self.velocity or self.north is None or self.east is None:
            return self
        depth = None if self.depth is None else max(0.0, self.depth + self.vz * dt)
        return replace(self, north=self.north + self.vn * dt, east=self.east + self.ve * dt, depth=depth)

    def command(self, north: float, east: float, heading: float, cruise: float) -> tuple[float, float, float | None]:
        """(heading, speed, vertical speed or None for "go to ``depth``") from where the vehicle is."""
        vn, ve = self.vn, self.ve
        if self.north is not None and self.east is not None:
            dn, de = self.north - north, self.east - east
            d = math.hypot(dn, de)
            if d > ARRIVED_M:
                k = min(1.0 / POSITION_TIME_S, cruise / d)
                vn, ve = vn + k * dn, ve + k * de
        speed = math.hypot(vn, ve)
        if speed > 1e-3:
            heading = math.atan2(ve, vn)
        elif self.yaw is not None:
            heading = self.yaw
        vz = None if self.depth is not None else self.vz
        return heading, speed, vz


def _mask(type_mask: int) -> tuple[bool, bool, bool] | None:
    """(position used, velocity used, yaw used) for the combinations ArduSub obeys, else None."""
    pos, vel = not type_mask & POS_IGNORE, not type_mask & VEL_IGNORE
    if type_mask & ACC_IGNORE != ACC_IGNORE or not (pos or vel):
        return None
    return pos, vel, not type_mask & YAW_IGNORE


def from_local_ned(msg, north: float, east: float, depth: float, heading: float, t: float) -> Target | None:
    """A SET_POSITION_TARGET_LOCAL_NED as ArduSub takes it, or None when ArduSub drops it."""
    frame = int(msg.coordinate_frame)
    used = _mask(int(msg.type_mask))
    if frame not in LOCAL_FRAMES or used is None:
        return None
    pos, vel, yaw = used
    values = [float(v) for v in (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.yaw)]
    if not all(math.isfinite(v) for v in values):
        return None
    x, y, z, vx, vy, vz, psi = values
    if frame in BODY_FRAMES:
        c, s = math.cos(heading), math.sin(heading)
        x, y = x * c - y * s, x * s + y * c
        vx, vy = vx * c - vy * s, vx * s + vy * c
    if frame != mav.MAV_FRAME_LOCAL_NED:
        x, y, z = x + north, y + east, z + depth
    return Target(
        north=x if pos else None,
        east=y if pos else None,
        depth=max(0.0, z) if pos else None,
        vn=vx if vel else 0.0,
        ve=vy if vel else 0.0,
        vz=vz if vel else 0.0,
        yaw=psi if yaw else None,
        velocity=vel,
        received=t,
    )


def from_global_int(msg, to_north_east, t: float) -> Target | None:
    """A SET_POSITION_TARGET_GLOBAL_INT; ``to_north_east(lat, lon)`` gives metres from the EKF origin."""
    used = _mask(int(msg.type_mask))
    if int(msg.coordinate_frame) not in GLOBAL_FRAMES or used is None:
        return None
    pos, vel, yaw = used
    values = [float(v) for v in (msg.alt, msg.vx, msg.vy, msg.vz, msg.yaw)]
    if not all(math.isfinite(v) for v in values):
        return None
    alt, vx, vy, vz, psi = values
    north = east = None
    if pos:
        lat, lon = msg.lat_int / 1e7, msg.lon_int / 1e7
        if not (abs(lat) <= 90 and abs(lon) <= 180):
            return None
        north, east = to_north_east(lat, lon)
    return Target(
        north=north,
        east=east,
        depth=max(0.0, -alt) if pos else None,
        vn=vx if vel else 0.0,
        ve=vy if vel else 0.0,
        vz=vz if vel else 0.0,
        yaw=psi if yaw else None,
        velocity=vel,
        received=t,
    )
