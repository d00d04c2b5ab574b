"""What crosses the front-seat/back-seat interface, at the precision MAVLink carries it.

The back-seat autonomy and the scorer never see the simulator's float64 state: they see
what a front-seat reports over MAVLink — positions and contact points as float32 metres
(``LOCAL_POSITION_NED``, ``OBSTACLE_DISTANCE_3D``), heading as float32 radians
(``ATTITUDE``), energy used in whole hectojoules (``BATTERY_STATUS.energy_consumed``) —
and the front-seat sees set-points as float32 velocity and yaw
(``SET_POSITION_TARGET_LOCAL_NED``).  The batch simulator applies exactly these
roundings too, so a scenario flown over MAVLink in software-in-the-loop scores the same,
bit for bit, as in a batch.

Frames: the simulator's local frame is x east, y north; MAVLink's LOCAL_NED is x north,
y east, z down.  Depth is a commanded state here: ``vz < 0`` asks the front-seat to
surface, ``vz > 0`` to stay at ``DEPTH_M``.
"""

from __future__ import annotations

import numpy as np

from sim.uuv.angles import wrap_angle

__all__ = [
    "report_position",
    "report_heading",
    "energy_consumed_hj",
    "battery_fraction",
    "encode_command",
    "decode_command",
    "depth_rate",
    "DEPTH_M",
    "HJ_PER_WH",
]

#: Running depth below the surface (m); LOCAL_POSITION_NED.z is 0 on the surface.
DEPTH_M = 2.0
#: 1 Wh = 3600 J = 36 hJ.
HJ_PER_WH = 36.0
#: Vertical speed in a set-point that says "surface" (negative, NED) or "stay down" (positive).
SURFACE_VZ = -0.5
DIVE_VZ = 0.5
#: A set-point says "surface" when its ``vz`` is at or above this rate upward: well past the depth-holding rate's
#: upward limit (:data:`MAX_UP_VZ`), so a vehicle held to its depth from below is never read as surfacing.
SURFACE_BELOW_VZ = 0.9 * SURFACE_VZ


def report_position(v: np.ndarray) -> np.ndarray:
    """A coordinate as reported in float32 metres."""
    return np.asarray(v, dtype=np.float32).astype(np.float64)


def report_heading(heading: np.ndarray) -> np.ndarray:
    """A compass heading (radians) as ATTITUDE.yaw reports it: float32 in (-pi, pi]."""
    h = wrap_angle(np.asarray(heading, dtype=float))
    return h.astype(np.float32).astype(np.float64)


def energy_consumed_hj(start_wh: np.ndarray, energy_wh: np.ndarray) -> np.ndarray:
    """Energy used so far in whole hectojoules (BATTERY_STATUS.energy_consumed, int32)."""
    return np.floor((np.asarray(start_wh) - np.asarray(energy_wh)) * HJ_PER_WH + 1e-9).astype(np.int64)


def battery_fraction(start_wh: np.ndarray, consumed_hj: np.ndarray, capacity_wh: float) -> np.ndarray:
    """Charge fraction the back-seat derives from the energy consumed and the known start charge."""
    return (np.asarray(start_wh, dtype=float) - np.asarray(consumed_hj, dtype=float) / HJ_PER_WH) / capacity_wh


def encode_command(
    heading: np.ndarray, speed: np.ndarray, surface: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vx north, vy east, vz down, yaw) float32 set-point for a through-water heading and speed."""
    heading = np.asarray(heading, dtype=float)
    speed = np.asarray(speed, dtype=float)
    vx = (speed * np.cos(heading)).astype(np.float32)
    vy = (speed * np.sin(heading)).astype(np.float32)
    vz = np.where(np.asarray(surface, dtype=bool), SURFACE_VZ, DIVE_VZ).astype(np.float32)
    return vx, vy, vz, report_heading(heading).astype(np.float32)


def decode_command(vx, vy, vz, yaw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The front-seat's reading of a set-point: (heading, speed, surface)."""
    vx = np.asarray(vx, dtype=np.float32).astype(np.float64)
    vy = np.asarray(vy, dtype=np.float32).astype(np.float64)
    heading = np.asarray(yaw, dtype=np.float32).astype(np.float64)
    return heading, np.hypot(vx, vy), np.asarray(vz, dtype=np.float32) <= np.float32(SURFACE_BELOW_VZ)


#: Depth-holding gain (1/s) and vertical speed limit (m/s) for a vehicle whose depth is a real state; upward it
#: stops short of the surfacing rate, so that a set-point's ``vz`` alone tells holding from surfacing.
DEPTH_GAIN = 0.25
MAX_VZ = 0.5
MAX_UP_VZ = 0.8 * -SURFACE_VZ


def depth_rate(depth: float, surface: bool, target_m: float = DEPTH_M) -> float:
    """Vertical velocity (NED, + down) that takes a real vehicle to ``target_m``, or up to the surface.

    A real autopilot in GUIDED integrates ``vz``: a constant "stay down" would drive it to the
    bottom.  So a back-seat flying a vehicle at its own pace holds depth with a proportional
    rate, limited to :data:`MAX_VZ` down and :data:`MAX_UP_VZ` up, and rises at :data:`SURFACE_VZ` to surface.
    """
    if surface:
        return SURFACE_VZ
    return float(np.clip(DEPTH_GAIN * (target_m - depth), -MAX_UP_VZ, MAX_VZ))
