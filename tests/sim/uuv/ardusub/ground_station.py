"""The ground station's side of the conformance sequences: a MAVLink client and the answers it reads.

:func:`canonical` reduces an answer to the fields a client acts on, so ArduSub's and ours
compare as strings (:mod:`tests.sim.uuv.ardusub.conformance`).
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Callable

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.params import ARDUSUB_PARAMETERS  # noqa: E402

mav = mavutil.mavlink

#: What counts as an answer; everything else (streamed telemetry) is ignored.
ANSWERS = frozenset(
    {
        "COMMAND_ACK",
        "PARAM_VALUE",
        "STATUSTEXT",
        "AUTOPILOT_VERSION",
        "HOME_POSITION",
        "GPS_GLOBAL_ORIGIN",
        "MESSAGE_INTERVAL",
        "FILE_TRANSFER_PROTOCOL",
    }
)
#: STATUSTEXT the firmware sends on its own (EKF, GPS), not in answer to anything.
SPONTANEOUS = re.compile(r"^(EKF\d|AHRS|GPS \d|Field Elevation|u-blox)")
#: The parameters our front-seat has (the others of ArduSub's list are not compared).
KEPT = {name for name, _, _ in ARDUSUB_PARAMETERS}


def canonical(msg) -> str:
    """The fields of an answer that a client acts on, as one comparable string."""
    kind = msg.get_type()
    if kind == "COMMAND_ACK":
        return f"COMMAND_ACK {msg.command} result={msg.result}"
    if kind == "PARAM_VALUE":
        index = "-1" if msg.param_index == 65535 else str(msg.param_index)
        return f"PARAM_VALUE {msg.param_id}={msg.param_value:g} type={msg.param_type} index={index}"
    if kind == "STATUSTEXT":  # the board's id (banner line 2) differs from one SITL instance to the next
        text = "<board id>" if re.fullmatch(r"[0-9a-f]{32}", msg.text) else msg.text
        return f"STATUSTEXT {msg.severity} {text!r}"
    if kind == "AUTOPILOT_VERSION":
        custom = bytes(msg.flight_custom_version).rstrip(b"\0").decode(errors="replace")
        return f"AUTOPILOT_VERSION caps=0x{msg.capabilities:X} sw=0x{msg.flight_sw_version:08X} git={custom}"
    if kind == "MESSAGE_INTERVAL":
        return f"MESSAGE_INTERVAL {msg.message_id} {msg.interval_us}"
    if kind == "FILE_TRANSFER_PROTOCOL":
        p = bytes(msg.payload)
        opcode = {128: "ACK", 129: "NAK"}.get(p[3], str(p[3]))
        error = f" error={p[12]}" if p[3] == 129 else ""
        return f"FTP {opcode} req={p[5]}{error}"
    if kind == "HEARTBEAT":
        return (
            f"HEARTBEAT type={msg.type} autopilot={msg.autopilot} base_mode={msg.base_mode} "
            f"custom_mode={msg.custom_mode} system_status={msg.system_status}"
        )
    if kind == "SYS_STATUS":
        return (
            f"SYS_STATUS present=0x{msg.onboard_control_sensors_present:X} "
            f"enabled=0x{msg.onboard_control_sensors_enabled:X} health=0x{msg.onboard_control_sensors_health:X}"
        )
    if kind == "EKF_STATUS_REPORT":
        return f"EKF_STATUS_REPORT flags=0x{msg.flags:X}"
    return kind  # HOME_POSITION, GPS_GLOBAL_ORIGIN: that it came is what counts


def is_answer(msg) -> bool:
    """Whether ``msg`` answers a request (not streamed telemetry, not what the firmware says on its own)."""
    kind = msg.get_type()
    if kind not in ANSWERS:
        return False
    if kind == "STATUSTEXT" and SPONTANEOUS.match(msg.text):
        return False
    # the firmware's own statistics, and what it saves on disarming
    return not (kind == "PARAM_VALUE" and (msg.param_id not in KEPT or msg.param_id.startswith("STAT_")))


class Client:
    """A ground station on one MAVLink link (system 250, component 190)."""

    def __init__(self, connection: str, grace_s: float):
        self.conn = mavutil.mavlink_connection(connection, source_system=250, source_component=190)
        self.grace_s = grace_s  # how long silence is awaited

    def close(self) -> None:
        self.conn.close()

    def hello(self, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.conn.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            if self.conn.wait_heartbeat(timeout=0.5) is not None:
                return
        raise TimeoutError("no HEARTBEAT from the vehicle")

    def drain(self) -> None:
        while self.conn.recv_match(blocking=False) is not None:
            pass

    def wait_for(self, kind: str, timeout: float = 10.0, ok: Callable = lambda m: True):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(type=kind, blocking=True, timeout=0.1)
            if msg is not None and ok(msg):
                return msg
        raise TimeoutError(f"no {kind}")

    def answers(self, expect: int | None, window: float) -> list:
        """Answers until ``expect`` of them came (then a short grace) or ``window`` seconds passed."""
        got: list = []
        deadline = time.monotonic() + window
        while time.monotonic() < deadline:
            msg = self.conn.recv_match(blocking=True, timeout=0.02)
            if msg is None or not is_answer(msg):
                continue
            got.append(msg)
            if expect is not None and len(got) >= expect:
                deadline = min(deadline, time.monotonic() + self.grace_s)
        return got

    def command(self, cmd: int, *params: float) -> None:
        p = [*params, *[0.0] * (7 - len(params))]
        self.conn.mav.command_long_send(1, 1, cmd, 0, *p)
