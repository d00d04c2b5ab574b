"""A vehicle's bus in one test: a loopback Zenoh session, frames a vehicle would send, and what comes out."""

from __future__ import annotations

import contextlib
import math
import os
import threading

os.environ.setdefault("MAVLINK20", "1")
import zenoh  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.session import open_session  # noqa: E402
from planner.common.telemetry import VehicleTelemetry  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from tests.support.loopback import free_port  # noqa: E402

VEHICLE = "uuv1"


@contextlib.contextmanager
def bus():
    """A peer session listening on a free loopback port, scouting off; closed on exit."""
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
    try:
        yield session
    finally:
        session.close()


class FakeVehicle:
    """Puts the frames an ArduSub would send (system 1, component 1) on ``keys.raw``, as the bridge does."""

    def __init__(self, session, mission, vehicle: str = VEHICLE):
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.frame = LocalFrame(mission.origin_lat, mission.origin_lon)
        self.pub = session.declare_publisher(keys.raw(vehicle))

    def send(self, msg) -> None:
        frame = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256
        self.pub.put(frame)

    def pose(self, time_ms: int, east: float, north: float, heading: float = 0.0, depth: float = 2.0) -> None:
        """ATTITUDE then GLOBAL_POSITION_INT, both stamped ``time_ms``."""
        lat, lon = self.frame.to_latlon(east, north)
        hdg = int(round(math.degrees(heading) % 360 * 100)) % 36000
        self.send(mavlink.MAVLink_attitude_message(time_ms, 0.0, 0.0, heading, 0.0, 0.0, 0.0))
        self.send(
            mavlink.MAVLink_global_position_int_message(
                time_ms,
                int(round(lat * 1e7)),
                int(round(lon * 1e7)),
                int(-depth * 1000),
                int(-depth * 1000),
                0,
                0,
                0,
                hdg,
            )
        )

    def battery(self, energy_hj: int, mah: int = -1, mv: int = 14800, battery_id: int = 0) -> None:
        volts = [mv] + [65535] * 9
        self.send(
            mavlink.MAVLink_battery_status_message(
                battery_id, 0, mavlink.MAV_BATTERY_TYPE_LION, 2000, volts, 500, mah, energy_hj, 80
            )
        )

    def heartbeat(self) -> None:
        m = mavlink
        self.send(
            m.MAVLink_heartbeat_message(
                m.MAV_TYPE_SUBMARINE, m.MAV_AUTOPILOT_ARDUPILOTMEGA, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4, 4, 3
            )
        )

    def close(self) -> None:
        self.pub.undeclare()


class Listener:
    """Everything put on ``key`` (a callback that only appends: it never blocks Zenoh)."""

    def __init__(self, session, key: str):
        self._lock = threading.Lock()
        self.samples: list[tuple[str, bytes, bytes | None]] = []
        self.sub = session.declare_subscriber(key, self._on)

    def _on(self, s) -> None:
        item = (str(s.key_expr), s.payload.to_bytes(), None if s.attachment is None else s.attachment.to_bytes())
        with self._lock:
            self.samples.append(item)

    def items(self, key: str | None = None) -> list[tuple[str, bytes, bytes | None]]:
        with self._lock:
            return [s for s in self.samples if key is None or s[0] == key]

    def payloads(self, key: str) -> list[bytes]:
        return [p for _, p, _ in self.items(key)]

    def close(self) -> None:
        try:
            self.sub.undeclare()
        except zenoh.ZError:
            pass


def decoded(frames) -> list:
    """The MAVLink messages of raw frames (``(key, payload, attachment)`` or bytes), in order."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    out = []
    for item in frames:
        payload = item if isinstance(item, bytes) else item[1]
        out.extend(m for m in parser.parse_buffer(payload) or [] if m.get_type() != "BAD_DATA")
    return out


def telemetry_of(mission, frames, battery_id: int = 0) -> VehicleTelemetry:
    """A consumer's :class:`VehicleTelemetry` after reading ``frames`` in order."""
    tel = VehicleTelemetry(LocalFrame(mission.origin_lat, mission.origin_lon), battery_id)
    for msg in decoded(frames):
        tel.add(msg)
    return tel
