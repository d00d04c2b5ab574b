"""ArduSub's telemetry streams: which message goes out how often, and how a client changes that.

A client of a real vehicle gets telemetry it never asked for, each message at its own
rate, and may change the rates two ways: per message (``MAV_CMD_SET_MESSAGE_INTERVAL``)
or per stream group (``REQUEST_DATA_STREAM``, the older way).  The bare front-seat must
answer both as ArduSub does, so this schedule is its own piece, in vehicle time.

Measured on ArduSub SITL 4.7.0-dev (speed-up 10, rates in vehicle time, nothing requested):
ATTITUDE, VFR_HUD 10 Hz (EXTRA1, EXTRA2); GLOBAL_POSITION_INT, LOCAL_POSITION_NED 3 Hz
(POSITION); SYSTEM_TIME, BATTERY_STATUS, EKF_STATUS_REPORT 3 Hz (EXTRA3); SYS_STATUS,
GPS_RAW_INT, MISSION_CURRENT 2 Hz (EXTENDED_STATUS); HEARTBEAT 1 Hz in no group.  SET_MESSAGE_INTERVAL:
-1 stops a message, 0 restores its group's *current* rate, an id ArduSub cannot stream
gets MAV_RESULT_DENIED.  REQUEST_DATA_STREAM is never acknowledged; ``start_stop`` 0 stops
the group (stream 0 = all groups, HEARTBEAT keeps going) and a new group rate replaces
the per-message intervals set in that group before.

Group rates live in the link's MAV1_* parameters (:mod:`sim.uuv.ardusub.params`) when a table is
given: REQUEST_DATA_STREAM writes them and a PARAM_SET of one changes the rate, as in
ArduPilot.
"""

from __future__ import annotations

import os

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.params import STREAM_PARAMETERS, ParameterTable  # noqa: E402

__all__ = ["StreamSchedule", "GROUPS", "DEFAULT_HZ", "message_id", "message_name"]

mav = mavutil.mavlink

#: ArduSub's stream groups (GCS_Mavlink.cpp), restricted to the messages the bare front-seat sends.
GROUPS: dict[int, tuple[str, ...]] = {
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: ("SYS_STATUS", "GPS_RAW_INT", "MISSION_CURRENT"),
    mav.MAV_DATA_STREAM_POSITION: ("GLOBAL_POSITION_INT", "LOCAL_POSITION_NED"),
    mav.MAV_DATA_STREAM_EXTRA1: ("ATTITUDE",),
    mav.MAV_DATA_STREAM_EXTRA2: ("VFR_HUD",),
    mav.MAV_DATA_STREAM_EXTRA3: ("SYSTEM_TIME", "BATTERY_STATUS", "EKF_STATUS_REPORT"),
}
#: ArduSub's default group rates (SRn_* parameters, Hz), as measured.
DEFAULT_HZ: dict[int, float] = {
    mav.MAV_DATA_STREAM_RAW_SENSORS: 2.0,
    mav.MAV_DATA_STREAM_EXTENDED_STATUS: 2.0,
    mav.MAV_DATA_STREAM_RC_CHANNELS: 2.0,
    mav.MAV_DATA_STREAM_POSITION: 3.0,
    mav.MAV_DATA_STREAM_EXTRA1: 10.0,
    mav.MAV_DATA_STREAM_EXTRA2: 10.0,
    mav.MAV_DATA_STREAM_EXTRA3: 3.0,
}
#: Messages outside every group, with their fixed default rate (Hz).
UNGROUPED_HZ: dict[str, float] = {"HEARTBEAT": 1.0}
#: The fastest a message goes out here (ArduPilot's own limit is its loop rate; ours is the wall clock).
MAX_HZ = 50.0


def message_id(name: str) -> int:
    return int(getattr(mav, f"MAVLINK_MSG_ID_{name}"))


def message_name(msg_id: int) -> str | None:
    """The streamable message with this id, or None."""
    return _NAMES.get(int(msg_id))


_GROUP_OF = {name: group for group, names in GROUPS.items() for name in names}
_NAMES = {message_id(name): name for name in (*_GROUP_OF, *UNGROUPED_HZ)}


class StreamSchedule:
    """When each streamed message is next due, in vehicle seconds."""

    def __init__(self, now: float = 0.0, params: ParameterTable | None = None):
        self.params = params
        self.group_hz = dict(DEFAULT_HZ)
        self.override: dict[str, float] = {}  # message -> Hz (0 = stopped), from SET_MESSAGE_INTERVAL
        self.next_due: dict[str, float] = {name: now for name in _NAMES.values()}

    def hz(self, name: str) -> float:
        if name in self.override:
            return self.override[name]
        if name in UNGROUPED_HZ:
            return UNGROUPED_HZ[name]
        return self.group_rate(_GROUP_OF[name])

    def group_rate(self, group: int) -> float:
        if self.params is not None and group in STREAM_PARAMETERS:
            return max(self.params.stream_hz(group), 0.0)
        return self.group_hz[group]

    def retime_all(self, now: float) -> None:
        """After a group rate changed: every message is next due within its new interval."""
        for name in self.next_due:
            self._retime(name, now)

    def interval_us(self, msg_id: int) -> int | None:
        """MESSAGE_INTERVAL's answer: microseconds, -1 when stopped, None for an id not streamed."""
        name = message_name(msg_id)
        if name is None:
            return None
        hz = self.hz(name)
        return int(round(1e6 / hz)) if hz > 0 else -1

    def due(self, now: float) -> list[str]:
        """The messages due at vehicle time ``now``; each is rescheduled one interval on."""
        out = []
        for name, when in self.next_due.items():
            if now + 1e-9 < when:
                continue
            hz = min(self.hz(name), MAX_HZ)
            if hz <= 0:
                self.next_due[name] = float("inf")
                continue
            out.append(name)
            period = 1.0 / hz
            # keep the cadence; after a stall (a slow wall clock) start again from now
            self.next_due[name] = when + period if when + period > now else now + period
        return out

    def next_time(self) -> float:
        return min(self.next_due.values())

    def _retime(self, name: str, now: float) -> None:
        hz = min(self.hz(name), MAX_HZ)
        if hz <= 0:
            self.next_due[name] = float("inf")
        else:
            self.next_due[name] = min(self.next_due[name], now + 1.0 / hz)

    def set_interval(self, msg_id: int, interval_us: float, now: float) -> int:
        """MAV_CMD_SET_MESSAGE_INTERVAL; returns the MAV_RESULT ArduSub gives."""
        name = message_name(msg_id)
        if name is None:
            return mav.MAV_RESULT_DENIED  # ArduSub: "No ap_message for mavlink id (N)"
        us = float(interval_us)
        if us == 0:
            self.override.pop(name, None)  # back to the group's current rate
        elif us == -1:
            self.override[name] = 0.0
        else:
            self.override[name] = 1e6 / min(max(us, 1000.0), 60e6)  # ArduPilot clamps to 1 ms .. 60 s
        self._retime(name, now)
        return mav.MAV_RESULT_ACCEPTED

    def request_data_stream(self, stream_id: int, rate_hz: int, start_stop: int, now: float) -> None:
        """REQUEST_DATA_STREAM (no answer is sent): set one group's rate, or all groups' (stream 0)."""
        if start_stop not in (0, 1):
            return
        hz = float(rate_hz) if start_stop == 1 else 0.0
        groups = list(DEFAULT_HZ) if stream_id == mav.MAV_DATA_STREAM_ALL else [int(stream_id)]
        for group in groups:
            if group not in DEFAULT_HZ:
                continue
            self.group_hz[group] = hz
            if self.params is not None and group in STREAM_PARAMETERS:
                self.params.set(STREAM_PARAMETERS[group], hz)
            for name in GROUPS.get(group, ()):
                self.override.pop(name, None)
                self._retime(name, now)
