"""When a freshly booted ArduSub knows where it is, and what it reports until then.

A client that arms and switches to GUIDED the moment it hears a heartbeat fails on a
real vehicle: the EKF needs GPS for a while before it has a horizontal position, and
ArduSub refuses the position modes until it does.  This is that timeline, compressed to
``ready_s`` vehicle seconds, so the bare front-seat teaches clients to wait for it.

Measured on ArduSub SITL 4.7.0-dev (vehicle seconds since boot, speed-up 10):
streaming starts at 5.3 s with EKF_STATUS_REPORT.flags 0x00A7 (attitude, horizontal and
vertical velocity, absolute vertical position, constant-position mode); GPS_RAW_INT
fix_type 0 and GLOBAL_POSITION_INT lat = lon = 0 until the GPS is detected (9.4 s), the
GPS position from then on; "EKF3 IMU0 origin set" at 19.5 s; "EKF3 IMU0 is using GPS" at
41.1 s, flags 0x033F (+ relative and absolute horizontal position, predicted horizontal
position) from 41.3 s.  LOCAL_POSITION_NED is not sent at all before that.  Until then
DO_SET_MODE GUIDED or POSHOLD gets MAV_RESULT_FAILED with STATUSTEXT "Mode change failed:
GUIDED requires position"; MANUAL, STABILIZE, ALT_HOLD and SURFACE are accepted, and so is
arming (ARMING_CHECK 448).  Here the GPS is found after a quarter of ``ready_s`` and the
origin and position come together at ``ready_s``.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["EkfReadiness", "FLAGS_BOOT", "FLAGS_READY", "POSITION_MODES"]

#: EKF_STATUS_REPORT.flags before the horizontal position is known (ArduSub, measured).
FLAGS_BOOT = 0x00A7
#: ... and once it is.
FLAGS_READY = 0x033F
#: ArduSub modes that require a position (ArduSub's Mode::requires_GPS): AUTO, GUIDED, CIRCLE, POSHOLD.
POSITION_MODES = frozenset({3, 4, 7, 16})
#: The GPS is detected this fraction of the way to readiness (ArduSub: 9.4 s of 41 s).
GPS_FRACTION = 0.25


@dataclass(frozen=True)
class EkfReadiness:
    ready_s: float = 5.0

    def gps_found(self, t: float) -> bool:
        return t >= GPS_FRACTION * self.ready_s

    def ready(self, t: float) -> bool:
        return t >= self.ready_s

    def flags(self, t: float) -> int:
        return FLAGS_READY if self.ready(t) else FLAGS_BOOT

    def mode_allowed(self, mode: int, t: float) -> bool:
        return mode not in POSITION_MODES or self.ready(t)
