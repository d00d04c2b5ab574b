"""The vehicle side of MAVLink's mission protocol, answered message by message as ArduSub answers it.

A ground station uploads, downloads and clears three lists this way: the mission
(waypoints), the fence and the rally points (``mission_type`` 0, 1, 2).  The reference is
ArduPilot's ``MissionItemProtocol*.cpp`` and ``AP_Mission.cpp`` as ArduSub SITL 4.7.0-dev
runs them (probed on loopback, vehicle time):

- Upload: MISSION_COUNT -> the vehicle asks for each item with MISSION_REQUEST (the
  deprecated form: that is what the firmware sends), re-asks every second of vehicle time,
  and gives up 8 s after the last item with MISSION_ACK OPERATION_CANCELLED and "Mission
  upload timeout".  The last item gets MISSION_ACK ACCEPTED, then "Flight plan received"
  (mission) or "Fence Indexed OK" (fence).  Items replace the stored list in place: the list
  is cut to the new count at MISSION_COUNT, so an upload aborted half-way keeps the old
  items behind the new ones.  MISSION_ITEM (float lat/lon) is accepted with a one-time
  warning; a count of 0 empties the list (ACCEPTED); a count above 655 gets NO_SPACE.
  What a download gives back is what AP_Mission stores: a location's frame as GLOBAL,
  GLOBAL_RELATIVE_ALT or GLOBAL_TERRAIN_ALT (never the _INT forms), and only the parameters
  a command uses (a NAV_WAYPOINT's acceptance radius comes back 0).
- Bad items: a wrong ``seq`` gets INVALID_SEQUENCE and the upload goes on; an unknown
  command gets UNSUPPORTED, an unknown frame UNSUPPORTED_FRAME, a latitude or longitude out
  of range INVALID_PARAM5_X / INVALID_PARAM6_Y, and each of those ends the upload.  An item
  outside an upload gets ERROR; another system's MISSION_COUNT during an upload, DENIED.
- Download: MISSION_REQUEST_LIST -> MISSION_COUNT; MISSION_REQUEST_INT -> MISSION_ITEM_INT
  (MISSION_REQUEST -> MISSION_ITEM and a one-time warning).  Seq 0 of the mission is always
  the vehicle's home, whatever was uploaded there.  A seq past the end gets MISSION_COUNT
  and MISSION_ACK INVALID_SEQUENCE.  During an upload both are DENIED.
- MISSION_CLEAR_ALL empties the list (cancelling an upload in progress), ACCEPTED.
  ``mission_type`` ALL (255) or any other unknown type gets UNSUPPORTED for everything.
- MISSION_CURRENT (streamed with SYS_STATUS, and sent at once whenever it changes): ``seq``
  the current item, ``total`` the items after home, ``mission_state`` NO_MISSION (1) with
  no item after home, else NOT_STARTED (2), ACTIVE (3) or COMPLETE (5); ``mission_mode``
  always 0 (ArduSub fills in no mode).  MISSION_SET_CURRENT to an item that exists changes
  ``seq`` with no acknowledgement (none at all otherwise); MAV_CMD_DO_SET_MISSION_CURRENT
  is ACCEPTED or DENIED.
- A vehicle flying AUTO (:mod:`sim.uuv.ardusub.auto`) announces each item as it starts it ("Mission:
  1 WP", "Mission: 2 LoitTime") and reports it done with MISSION_ITEM_REACHED and "Reached
  command #N" (nothing after a loiter); MISSION_CURRENT goes ACTIVE (3), then COMPLETE (5)
  after the last item, its ``seq`` staying there.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

__all__ = ["MissionServer", "Item", "MAX_ITEMS", "UPLOAD_TIMEOUT_S", "REQUEST_RETRY_S"]

mav = mavutil.mavlink

#: Largest mission ArduSub SITL stores ("Only 655 items are supported").
MAX_ITEMS = 655
#: An upload is cancelled this long (vehicle seconds) after the last item arrived.
UPLOAD_TIMEOUT_S = 8.0
#: An item not received within this long (vehicle seconds) is asked for again.
REQUEST_RETRY_S = 1.0

MISSION, FENCE, RALLY = mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE, mav.MAV_MISSION_TYPE_RALLY
#: Commands AP_Mission stores in a mission (AP_Mission::mavlink_int_to_mission_cmd); any other is UNSUPPORTED.
MISSION_COMMANDS = frozenset(
    {16, 17, 18, 19, 20, 21, 22, 30, 31, 82, 83, 92, 93, 94, 112, 114, 115, 176, 177, 178, 179, 181, 182, 183, 184}
    | {189, 191, 192, 195, 196, 197, 201, 202, 203, 205, 206, 207, 208, 210, 211, 212, 213, 214, 215, 222, 223}
    | {1000, 2000, 2001, 2500, 2501, 30001, 30002, 42600, 42702}
)
#: The fence's items (polygon and circle, inclusion and exclusion, return point); the rally's.
FENCE_COMMANDS = frozenset({5000, 5001, 5002, 5003, 5004})
RALLY_COMMANDS = frozenset({5100})
#: Commands whose x, y are a latitude and longitude (AP_Mission::stored_in_location).
LOCATION_COMMANDS = frozenset({16, 17, 18, 19, 20, 21, 22, 30, 31, 82, 83, 94, 179, 192, 195, 201})
#: Frames AP_Mission takes for a location: GLOBAL, MISSION, RELATIVE_ALT, their _INT forms, terrain.
LOCATION_FRAMES = frozenset({0, 2, 3, 5, 6, 10, 11})
#: The frame a download gives back for each (absolute, relative or terrain altitude, never _INT).
_STORED_FRAME = {0: 0, 2: 0, 5: 0, 3: 3, 6: 3, 10: 10, 11: 10}


@dataclass(frozen=True)
class Item:
    """One stored item, as MISSION_ITEM_INT carries it (x, y in degE7 for locations)."""

    frame: int
    command: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    #: The MISSION_ITEM(_INT) it came in (None for home).
    message: Any = field(default=None, compare=False, repr=False)


@dataclass
class _Upload:
    mission_type: int
    sysid: int
    compid: int
    count: int
    next_seq: int = 0
    last_received: float = 0.0
    last_request: float = 0.0


class MissionServer:
    """The mission, fence and rally lists of one vehicle and the protocol around them (module docstring).

    ``conn`` is the vehicle's pymavlink connection, ``home`` (lat, lon, alt) seq 0 of the
    mission, ``status(severity, text)`` sends a STATUSTEXT, ``clock()`` is vehicle seconds.
    Call :meth:`handle` with every received message and :meth:`update` from the vehicle's loop.
    """

    def __init__(
        self,
        conn,
        home: tuple[float, float, float],
        status: Callable[[int, str], None],
        clock: Callable[[], float],
    ):
        self.conn, self.status, self.clock = conn, status, clock
        self.home = Item(mav.MAV_FRAME_GLOBAL, mav.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, *_degE7(home[:2]), home[2])
        #: Stored lists by mission type; the mission's seq 0 is home (one item at boot, as ArduSub).
        self.lists: dict[int, list[Item]] = {MISSION: [self.home], FENCE: [], RALLY: []}
        self.current = 0
        self.state = mav.MISSION_STATE_NO_MISSION
        self.upload: _Upload | None = None
        self.uploads_completed = 0
        self._warned: set[str] = set()

    # -- what the rest of the vehicle reads -----------------------------------------------
    @property
    def mission(self) -> list[Item]:
        """The mission with seq 0 as home."""
        items = self.lists[MISSION]
        return [self.home, *items[1:]] if items else []

    def waypoint(self, seq: int) -> Item:
        return self.mission[seq]

    def send_current(self) -> None:
        """MISSION_CURRENT as ArduSub fills it in."""
        total = max(len(self.lists[MISSION]) - 1, 0)
        state = self.state
        if total == 0:
            state = mav.MISSION_STATE_NO_MISSION
        elif state == mav.MISSION_STATE_NO_MISSION:
            state = mav.MISSION_STATE_NOT_STARTED
        self.conn.mav.mission_current_send(self.current, total, state, 0)

    def start_item(self, seq: int) -> None:
        """AUTO starts flying item ``seq``: "Mission: N <type>" and a MISSION_CURRENT at once."""
        command = self.mission[seq].command
        self.status(mav.MAV_SEVERITY_INFO, f"Mission: {seq} {_COMMAND_NAMES.get(command, str(command))}")
        self.current, self.state = seq, mav.MISSION_STATE_ACTIVE
        self.send_current()

    def reached(self, seq: int, next_seq: int | None = None) -> None:
        """AUTO finished item ``seq``: MISSION_ITEM_REACHED ("Reached command #N" after a waypoint),
        then item ``next_seq`` (default ``seq + 1``) starts, or the mission is COMPLETE."""
        self.conn.mav.mission_item_reached_send(seq)
        if self.mission[seq].command != mav.MAV_CMD_NAV_LOITER_TIME:  # ArduSub says nothing after a loiter
            self.status(mav.MAV_SEVERITY_INFO, f"Reached command #{seq}")
        next_seq = seq + 1 if next_seq is None else next_seq
        if next_seq < len(self.mission):
            self.start_item(next_seq)
        else:
            self.state = mav.MISSION_STATE_COMPLETE
            self.send_current()

    # -- MAVLink in -------------------------------------------------------------------------
    def handle(self, msg) -> bool:
        """Answer ``msg`` if it belongs to the mission protocol; True if it did."""
        kind = msg.get_type()
        if kind == "COMMAND_LONG" and int(msg.command) == mav.MAV_CMD_DO_SET_MISSION_CURRENT:
            ok = self._set_current(int(msg.param1))
            result = mav.MAV_RESULT_ACCEPTED if ok else mav.MAV_RESULT_DENIED
            self.conn.mav.command_ack_send(mav.MAV_CMD_DO_SET_MISSION_CURRENT, result)
            if ok:
                self.send_current()
            return True
        if kind == "MISSION_SET_CURRENT":
            if self._set_current(int(msg.seq)):
                self.send_current()
            return True
        handler = _HANDLERS.get(kind)
        if handler is None:
            return False
        if kind == "MISSION_ACK":
            return True  # the end of a download: nothing to answer
        mission_type = int(getattr(msg, "mission_type", MISSION))
        if mission_type not in self.lists:
            self._ack(msg, mav.MAV_MISSION_UNSUPPORTED, mission_type)
            return True
        getattr(self, handler)(msg, mission_type)
        return True

    def update(self) -> None:
        """Re-ask for the awaited item, or cancel an upload that stalled."""
        up = self.upload
        if up is None:
            return
        now = self.clock()
        if now - up.last_received > UPLOAD_TIMEOUT_S:
            self.upload = None
            self.conn.mav.mission_ack_send(up.sysid, up.compid, mav.MAV_MISSION_OPERATION_CANCELLED, up.mission_type)
            if up.mission_type == MISSION:
                self.status(mav.MAV_SEVERITY_WARNING, "Mission upload timeout")
        elif now - up.last_request > REQUEST_RETRY_S:
            self._request(up, now)

    # -- the protocol ----------------------------------------------------------------------
    def _count(self, msg, mission_type: int) -> None:
        up, src = self.upload, (msg.get_srcSystem(), msg.get_srcComponent())
        if up is not None and (up.sysid, up.compid) != src:
            self._ack(msg, mav.MAV_MISSION_DENIED, mission_type)
            return
        count = int(msg.count)
        if count > MAX_ITEMS:
            self._ack(msg, mav.MAV_MISSION_NO_SPACE, mission_type)
            self.status(mav.MAV_SEVERITY_WARNING, f"Only {MAX_ITEMS} items are supported")
            return
        self.upload = None
        del self.lists[mission_type][count:]
        if count == 0:
            self._complete(msg, mission_type)
            return
        now = self.clock()
        self.upload = _Upload(mission_type, *src, count, last_received=now)
        self._request(self.upload, now)

    def _item(self, msg, mission_type: int) -> None:
        up = self.upload
        if up is None or up.mission_type != mission_type:
            self._ack(msg, mav.MAV_MISSION_ERROR, mission_type)
            return
        if int(msg.seq) != up.next_seq:
            self._ack(msg, mav.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        if (msg.get_srcSystem(), msg.get_srcComponent()) != (up.sysid, up.compid):
            self._ack(msg, mav.MAV_MISSION_DENIED, mission_type)
            return
        if msg.get_type() == "MISSION_ITEM":
            self._warn_once("got MISSION_ITEM; GCS should send MISSION_ITEM_INT")
        item, result = _decode(msg, mission_type)
        if item is None:
            self.upload = None
            self._ack(msg, result, mission_type)
            return
        stored = self.lists[mission_type]
        if up.next_seq < len(stored):
            stored[up.next_seq] = item
        else:
            stored.append(item)
        up.next_seq += 1
        up.last_received = self.clock()
        if up.next_seq >= up.count:
            self.upload = None
            self._complete(msg, mission_type)
        else:
            self._request(up, up.last_received)

    def _complete(self, msg, mission_type: int) -> None:
        self._ack(msg, mav.MAV_MISSION_ACCEPTED, mission_type)
        self.uploads_completed += 1
        if mission_type == MISSION:
            self.status(mav.MAV_SEVERITY_INFO, "Flight plan received")
            self._new_mission()
        elif mission_type == FENCE:
            self.status(mav.MAV_SEVERITY_DEBUG, "Fence Indexed OK")

    def _request_list(self, msg, mission_type: int) -> None:
        if self.upload is not None:
            self._ack(msg, mav.MAV_MISSION_DENIED, mission_type)
            return
        n = len(self.lists[mission_type])
        self.conn.mav.mission_count_send(msg.get_srcSystem(), msg.get_srcComponent(), n, mission_type)

    def _request_item(self, msg, mission_type: int) -> None:
        if self.upload is not None:
            self._ack(msg, mav.MAV_MISSION_DENIED, mission_type)
            return
        seq = int(msg.seq)
        stored = self.mission if mission_type == MISSION else self.lists[mission_type]
        if seq == 0 and mission_type == MISSION:
            item = self.home  # ArduSub always lets home be read
        elif 0 <= seq < len(stored):
            item = stored[seq]
        else:
            src = (msg.get_srcSystem(), msg.get_srcComponent())
            self.conn.mav.mission_count_send(*src, len(stored), mission_type)  # "educate the GCS"
            self._ack(msg, mav.MAV_MISSION_INVALID_SEQUENCE, mission_type)
            return
        # ArduSub compares the command's id with the current index here, so "current" is almost never 1
        current = int(mission_type == MISSION and item.command == self.current)
        src = (msg.get_srcSystem(), msg.get_srcComponent())
        p = (item.param1, item.param2, item.param3, item.param4)
        if msg.get_type() == "MISSION_REQUEST":
            x, y = _float_xy(item)
            self.conn.mav.mission_item_send(
                *src, seq, item.frame, item.command, current, 1, *p, x, y, item.z, mission_type
            )
            self._warn_once("got MISSION_REQUEST; use MISSION_REQUEST_INT!")
        else:
            self.conn.mav.mission_item_int_send(
                *src, seq, item.frame, item.command, current, 1, *p, item.x, item.y, item.z, mission_type
            )

    def _clear_all(self, msg, mission_type: int) -> None:
        if self.upload is not None and self.upload.mission_type == mission_type:
            self.upload = None  # ArduSub SITL: a clear cancels the upload in progress
        self.lists[mission_type].clear()
        self._ack(msg, mav.MAV_MISSION_ACCEPTED, mission_type)
        if mission_type == MISSION:
            self._new_mission()
        elif mission_type == FENCE:
            self.status(mav.MAV_SEVERITY_DEBUG, "Fence Indexed OK")

    # -- helpers ------------------------------------------------------------------------------
    def _new_mission(self) -> None:
        self.current, self.state = 0, mav.MISSION_STATE_NOT_STARTED
        self.send_current()

    def _set_current(self, seq: int) -> bool:
        if not 0 < seq < len(self.lists[MISSION]):
            return False
        self.current = seq
        return True

    def _request(self, up: _Upload, now: float) -> None:
        up.last_request = now
        self.conn.mav.mission_request_send(up.sysid, up.compid, up.next_seq, up.mission_type)

    def _ack(self, msg, result: int, mission_type: int) -> None:
        self.conn.mav.mission_ack_send(msg.get_srcSystem(), msg.get_srcComponent(), result, mission_type)

    def _warn_once(self, text: str) -> None:
        if text not in self._warned:
            self._warned.add(text)
            self.status(mav.MAV_SEVERITY_WARNING, text)


#: How ArduSub names an item it starts (AP_Mission::Mission_Command::type()).
_COMMAND_NAMES = {16: "WP", 17: "LoitUnlim", 18: "LoitTurns", 19: "LoitTime", 20: "RTL", 21: "Land", 82: "SplineWP"}

_HANDLERS = {
    "MISSION_COUNT": "_count",
    "MISSION_ITEM_INT": "_item",
    "MISSION_ITEM": "_item",
    "MISSION_REQUEST_LIST": "_request_list",
    "MISSION_REQUEST_INT": "_request_item",
    "MISSION_REQUEST": "_request_item",
    "MISSION_CLEAR_ALL": "_clear_all",
    "MISSION_ACK": "",
}


def _degE7(latlon) -> tuple[int, int]:
    return int(round(latlon[0] * 1e7)), int(round(latlon[1] * 1e7))


def _float_xy(item: Item) -> tuple[float, float]:
    if item.command in (202, 203):  # DIGICAM: x, y are not a position
        return float(item.x), float(item.y)
    return item.x * 1e-7, item.y * 1e-7


def _decode(msg, mission_type: int) -> tuple[Item | None, int]:
    """The item to store, or None and the MAV_MISSION_RESULT ArduSub answers."""
    command, frame = int(msg.command), int(msg.frame)
    allowed = {MISSION: MISSION_COMMANDS, FENCE: FENCE_COMMANDS, RALLY: RALLY_COMMANDS}[mission_type]
    if command not in allowed:
        return None, mav.MAV_MISSION_UNSUPPORTED
    if msg.get_type() == "MISSION_ITEM" and command not in (202, 203):
        if not (abs(msg.x) <= 90 and abs(msg.y) <= 180):
            return None, (mav.MAV_MISSION_INVALID_PARAM5_X if abs(msg.x) > 90 else mav.MAV_MISSION_INVALID_PARAM6_Y)
        x, y = _degE7((msg.x, msg.y))
    else:
        x, y = int(msg.x), int(msg.y)
    if mission_type == MISSION and command in LOCATION_COMMANDS:
        if abs(x) > 900_000_000:
            return None, mav.MAV_MISSION_INVALID_PARAM5_X
        if abs(y) > 1_800_000_000:
            return None, mav.MAV_MISSION_INVALID_PARAM6_Y
        if frame not in LOCATION_FRAMES:
            return None, mav.MAV_MISSION_UNSUPPORTED_FRAME
    params = _as_stored(command, (msg.param1, msg.param2, msg.param3, msg.param4))
    if mission_type == MISSION and command in LOCATION_COMMANDS:
        frame = _STORED_FRAME[frame]  # AP_Mission keeps "relative" and "terrain" flags, not the frame
    item = Item(frame, command, *params, x, y, float(msg.z), msg)
    return item, mav.MAV_MISSION_ACCEPTED


def _as_stored(command: int, p: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
    """The parameters a download gives back: AP_Mission keeps only what it uses, in its own types.

    ArduSub SITL returns a NAV_WAYPOINT uploaded with an acceptance radius (param2) with
    param2 0, and a LOITER_TIME with param3 1 (clockwise); other commands keep their values here.
    """

    def u16(v: float) -> float:
        return float(min(max(int(v), 0), 65535))

    def sign(v: float) -> float:
        return -1.0 if v < 0 else 1.0

    if command in (16, 82):  # WAYPOINT, SPLINE_WAYPOINT: the delay at the point
        return u16(p[0]), 0.0, 0.0, 0.0
    if command == 17:  # LOITER_UNLIM: radius, its sign the direction
        return 0.0, 0.0, sign(p[2]) * u16(abs(p[2])), 0.0
    if command == 18:  # LOITER_TURNS: turns and radius in one byte each
        return float(int(p[0]) & 0xFF), 0.0, sign(p[2]) * float(int(abs(p[2])) & 0xFF), float(p[3] > 0)
    if command == 19:  # LOITER_TIME: seconds, direction, cross-track flag
        return u16(p[0]), 0.0, sign(p[2]), float(p[3] > 0)
    if command == 20:  # RETURN_TO_LAUNCH
        return 0.0, 0.0, 0.0, 0.0
    if command in (21, 22):  # LAND (abort altitude, yaw direction), TAKEOFF (pitch)
        return u16(p[0]), 0.0, 0.0, (sign(p[3]) if command == 21 else 0.0)
    return p
