"""The MAVLink mission upload protocol as a state machine with no I/O: the bridge sends and receives for it.

The ground side of MAVLink's mission upload (devguide ``services/mission.md``): send
``MISSION_COUNT``; the vehicle asks for each item with ``MISSION_REQUEST_INT`` (ArduSub asks
with the deprecated ``MISSION_REQUEST``, and both are answered with ``MISSION_ITEM_INT``);
after the last item the vehicle answers ``MISSION_ACK``. :class:`MissionUpload` decides what
to send next from what came in and from the clock it is given, so every branch is tested
without a socket.

What ArduPilot does (``libraries/GCS_MAVLink/MissionItemProtocol.cpp``, checked on ArduSub
SITL): seq 0 is home, and the vehicle keeps its own home there whatever is uploaded; an item
out of sequence gets a NACK (``MAV_MISSION_INVALID_SEQUENCE``) and the vehicle asks again, so a
NACK does not end the upload, but an item it cannot store gets a NACK that does; it asks again
for an item it has not received after 1 s of *vehicle* time and cancels the upload
(``MAV_MISSION_OPERATION_CANCELLED``) after 8 s. Hence the rules here:

- a request for an item in range is answered, again if asked again;
- progress is a request for a later item than any before, or the final ``MAV_MISSION_ACCEPTED``;
  the timeout (1.5 s by default, as the devguide recommends) runs from the last progress;
- at the timeout with no progress, the last message is sent again, up to ``retries`` times,
  then :class:`~rapt.errors.LinkTimeoutError` names the step that stalled;
- ``MAV_MISSION_INVALID_SEQUENCE`` (an item that crossed a request, or came twice) ends nothing:
  the vehicle still waits for the item it asked for, and the timeout sends it again;
- any other NACK is recorded, and the vehicle has a whole timeout from it to ask for an item again
  (within the time the retries allow since the last progress); if it does not, the upload ends
  with that NACK as its result (a vehicle that asks again goes on as if it had not come);
- ``MAV_MISSION_ACCEPTED`` counts only once the last item has gone out (an earlier one is
  another upload's), and messages of another ``mission_type`` are not ours.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, fields
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from rapt.errors import InputError, LinkTimeoutError  # noqa: E402

from .frames import mavlink2  # noqa: E402

__all__ = ["MissionItem", "MissionUpload", "COUNT", "MISSION_TYPES", "mission_items", "describe"]

#: What :class:`MissionUpload` returns to mean "send MISSION_COUNT" (items are sent by their seq >= 0).
COUNT = -1
#: MAV_MISSION_TYPE values an upload may carry: mission, fence, rally.
MISSION_TYPES = {
    mavlink2.MAV_MISSION_TYPE_MISSION: "mission",
    mavlink2.MAV_MISSION_TYPE_FENCE: "fence",
    mavlink2.MAV_MISSION_TYPE_RALLY: "rally",
}

_INT_RANGES = {
    "seq": (0, 0xFFFF),
    "frame": (0, 0xFF),
    "command": (0, 0xFFFF),
    "current": (0, 0xFF),
    "autocontinue": (0, 0xFF),
    "x": (-(2**31), 2**31 - 1),
    "y": (-(2**31), 2**31 - 1),
}


@dataclass(frozen=True)
class MissionItem:
    """One ``MISSION_ITEM_INT``: ``x``/``y`` are latitude/longitude in degE7 (ints), ``z`` in metres (up-positive
    in the GLOBAL frames, so a depth is negative); ``param1..param4`` may be NaN where the command says so."""

    seq: int
    frame: int
    command: int
    current: int = 0
    autocontinue: int = 1
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0

    @classmethod
    def waypoint(
        cls,
        seq: int,
        lat: float,
        lon: float,
        alt_m: float,
        *,
        hold_s: float = 0.0,
        frame: int = mavlink2.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
    ) -> MissionItem:
        """A MAV_CMD_NAV_WAYPOINT (16) at ``lat``/``lon`` degrees, ``alt_m`` up-positive (``-depth``)."""
        return cls(
            seq=seq,
            frame=frame,
            command=mavlink2.MAV_CMD_NAV_WAYPOINT,
            param1=hold_s,
            x=int(round(lat * 1e7)),
            y=int(round(lon * 1e7)),
            z=alt_m,
        )

    @classmethod
    def from_message(cls, msg: Any) -> MissionItem:
        """The item a pymavlink ``MAVLink_mission_item_int_message`` carries (its targets and mission_type aside)."""
        return cls(**{f.name: getattr(msg, f.name) for f in fields(cls)})

    def to_message(self, target_system: int, target_component: int, mission_type: int) -> Any:
        """The ``MISSION_ITEM_INT`` that answers a request for this item."""
        return mavlink2.MAVLink_mission_item_int_message(
            target_system,
            target_component,
            self.seq,
            self.frame,
            self.command,
            self.current,
            self.autocontinue,
            self.param1,
            self.param2,
            self.param3,
            self.param4,
            self.x,
            self.y,
            self.z,
            mission_type,
        )


def mission_items(items: Iterable[Any], what: str = "items") -> list[MissionItem]:
    """Validate an upload: MissionItem or MISSION_ITEM_INT messages, item i with seq i; errors name ``items[i].field``."""
    if isinstance(items, (str, bytes)) or not isinstance(items, Iterable):
        raise InputError(f"{what}: expected a sequence of MissionItem or MISSION_ITEM_INT messages, got {items!r}")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, mavlink2.MAVLink_mission_item_int_message):
            item = MissionItem.from_message(item)
        elif not isinstance(item, MissionItem):
            raise InputError(
                f"{what}[{i}]: expected a MissionItem or a MISSION_ITEM_INT message, got {type(item).__name__}"
            )
        for name, (low, high) in _INT_RANGES.items():
            value = getattr(item, name)
            if not (isinstance(value, int) and not isinstance(value, bool) and low <= value <= high):
                raise InputError(f"{what}[{i}].{name}: expected an int in {low}..{high}, got {value!r}")
        for name in ("param1", "param2", "param3", "param4", "z"):
            value = getattr(item, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise InputError(f"{what}[{i}].{name}: expected a number, got {value!r}")
        if not math.isfinite(item.z):
            raise InputError(f"{what}[{i}].z: expected a finite number, got {item.z!r}")
        if item.seq != i:
            raise InputError(f"{what}[{i}].seq: expected {i} (items go in order from 0), got {item.seq}")
        out.append(item)
    if len(out) > 0xFFFF:
        raise InputError(f"{what}: at most 65535 items fit a MISSION_COUNT, got {len(out)}")
    return out


class MissionUpload:
    """One upload of ``count`` items, driven by :meth:`start`, :meth:`on_request`, :meth:`on_ack` and
    :meth:`on_timeout` (call it once ``now >= deadline``); each returns what to send: :data:`COUNT`
    or item seqs. Ends with :attr:`done` and :attr:`result` (a MAV_MISSION_RESULT)."""

    def __init__(
        self,
        count: int,
        *,
        mission_type: int = mavlink2.MAV_MISSION_TYPE_MISSION,
        timeout_s: float = 1.5,
        retries: int = 5,
        what: str = "upload_mission",
    ):
        if not (isinstance(count, int) and 0 <= count <= 0xFFFF):
            raise InputError(f"count: expected an int in 0..65535, got {count!r}")
        if mission_type not in MISSION_TYPES:
            raise InputError(
                f"mission_type: expected one of {sorted(MISSION_TYPES)} (mission, fence, rally), got {mission_type!r}"
            )
        if not (isinstance(timeout_s, (int, float)) and not isinstance(timeout_s, bool) and timeout_s > 0):
            raise InputError(f"timeout: expected a number of seconds > 0, got {timeout_s!r}")
        if not (isinstance(retries, int) and not isinstance(retries, bool) and retries >= 0):
            raise InputError(f"retries: expected an int >= 0, got {retries!r}")
        self.count = count
        self.mission_type = mission_type
        self.timeout_s = float(timeout_s)
        self.retries = retries
        self.what = what
        self.done = False
        #: The MAV_MISSION_RESULT the upload ended with (None while it runs).
        self.result: int | None = None
        #: The time by which progress must come, or :meth:`on_timeout` is due.
        self.deadline = math.inf
        #: Every NACK (MAV_MISSION_RESULT other than ACCEPTED) received, in order.
        self.nacks: list[int] = []
        #: Messages sent again: after a timeout, or because the vehicle asked again.
        self.resent = 0
        self._asked = -1  # the highest seq requested so far (-1: none yet)
        self._last = COUNT  # what went out last: sent again on a timeout
        self._tries = 0  # timeouts since the last progress
        self._nack_pending = False  # a NACK came after the last request
        self._give_up = math.inf  # NACKs never move the deadline past this

    @property
    def step(self) -> str:
        """The step the upload waits on, as an error names it."""
        if self.count == 0:
            return "MISSION_COUNT 0: no MISSION_ACK"
        if self._asked < 0:
            return "MISSION_COUNT: no MISSION_REQUEST for item 0"
        if self._asked < self.count - 1:
            return f"item {self._asked}: no MISSION_REQUEST for item {self._asked + 1}"
        return f"item {self._asked}: no MISSION_ACK"

    def start(self, now: float) -> list[int]:
        """Begin: send MISSION_COUNT."""
        self._progress(now)
        return [COUNT]

    def on_request(self, seq: int, mission_type: int, now: float) -> list[int]:
        """A MISSION_REQUEST_INT or MISSION_REQUEST for ``seq``: the item to send, if it is one of ours."""
        if self.done or mission_type != self.mission_type or not 0 <= seq < self.count:
            return []
        self._nack_pending = False  # still asking: the vehicle goes on with the upload
        if seq > self._asked:
            self._asked = seq
            self._progress(now)
        else:
            self.resent += 1  # the vehicle lost our item, or the requests crossed it: answer again
        self._last = seq
        return [seq]

    def on_ack(self, result: int, mission_type: int, now: float) -> list[int]:
        """A MISSION_ACK: ACCEPTED after the last item ends the upload; a NACK is kept (see the module)."""
        if self.done or mission_type != self.mission_type:
            return []
        if result == mavlink2.MAV_MISSION_ACCEPTED:
            if self._asked == self.count - 1:  # count 0: at once; otherwise once the last item was asked for
                self._finish(result)
            return []
        self.nacks.append(result)
        if result == mavlink2.MAV_MISSION_INVALID_SEQUENCE:
            return []  # an item that crossed a request, or came twice: the vehicle waits for the one it asked for
        self._nack_pending = True
        # give the vehicle a whole timeout to ask again, within the time the retries allow since progress
        self.deadline = max(self.deadline, min(now + self.timeout_s, self._give_up))
        return []

    def on_timeout(self, now: float) -> list[int]:
        """No progress by :attr:`deadline`: end with a pending NACK, send the last message again, or raise."""
        if self.done:
            return []
        if self._nack_pending:
            self._finish(self.nacks[-1])
            return []
        if self._tries >= self.retries:
            raise LinkTimeoutError(f"{self.what}: {self.step} after {self._tries + 1} tries, {self.timeout_s:g} s each")
        self._tries += 1
        self.resent += 1
        self.deadline = now + self.timeout_s
        return [self._last]

    def _progress(self, now: float) -> None:
        self._tries = 0
        self._nack_pending = False
        self.deadline = now + self.timeout_s
        self._give_up = now + (self.retries + 1) * self.timeout_s

    def _finish(self, result: int) -> None:
        self.done, self.result = True, result
        self.deadline = math.inf


def describe(result: int) -> str:
    """MAV_MISSION_RESULT's name, e.g. ``MAV_MISSION_ACCEPTED`` (or the number if unknown)."""
    entry = mavlink2.enums["MAV_MISSION_RESULT"].get(result)
    return entry.name if entry is not None else str(result)
