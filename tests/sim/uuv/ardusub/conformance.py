"""Does the simulated front-seat answer a ground station as ArduSub does?  Message by message.

The sequences a ground station sends on connect and in use (heartbeat watch, AUTOPILOT_VERSION,
the parameter list, reads and sets including bad ones, mode changes valid and invalid,
arm/disarm, an unsupported command, stream rates set and by default, MAVLink FTP, GUIDED
velocity targets and their timeout, mission upload and download) go over real MAVLink on
loopback, first to ArduSub SITL (the firmware is the reference), then to
:class:`sim.uuv.ardusub.frontseat.FrontSeat` in both flavours; each answer is reduced to the
fields that matter (:func:`canonical`) and the two are compared row by row (a rate row
matches when it names the same messages at rates within a factor of 2, per vehicle second).  A row matches
or carries a reason from :data:`ALLOWED`; anything else fails ``test_conformance.py``.

ArduSub's answers are recorded once into ``ardusub_answers.json`` next to this module (with the
firmware version), so the test needs no firmware::

    python -m tests.sim.uuv.ardusub.conformance                # ours (both flavours) against the recording
    python -m tests.sim.uuv.ardusub.conformance --sitl         # ... and live against ArduSub SITL ($ARDUSUB_SITL)
    python -m tests.sim.uuv.ardusub.conformance --record       # record ArduSub's answers into the fixture

The client is system 250, not the ground-station id 255, so SITL's GCS failsafe stays out of
the sequences.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.params import ARDUSUB_PARAMETERS, FIRMWARE  # noqa: E402

mav = mavutil.mavlink

FIXTURE = Path(__file__).with_name("ardusub_answers.json")
FLAVOURS = ("lockstep", "bare")

#: Rows allowed to differ, and why (the conformance table prints the reason).
ALLOWED: dict[str, str] = {
    "PARAM_REQUEST_LIST": "a subset of ArduSub's 1,386: those a ground station reads on connect and our model maps to",
    "PARAM_REQUEST_LIST banner": "line 2 is the board's unique id; ours names the simulator",
    "FTP open @PARAM/param.pck": "the banner after it: line 2 is the board's unique id; ours names the simulator",
    "boot WPNAV_SPEED": "set from the mission's cruise speed: our vehicle is not a BlueROV2",
    "boot BATT_CAPACITY": "set from the mission's battery (Wh at 14.8 V)",
    "default streams: message types": "ArduSub streams 32 types; ours the 11 a back-seat or ground station reads "
    "(no IMU, RC, servo, pressure or rangefinder hardware is simulated); their rates agree (next row)",
    "GUIDED velocity target: braking": "our vehicle is the mission's torpedo model, which coasts down over seconds; "
    "ArduSub's BlueROV2 falls to 0.2 m/s within 0.3 s, then drifts at 0.2-0.14 m/s",
}
#: Rows only the lock-step flavour may differ in, and why.
ALLOWED_LOCKSTEP: dict[str, str] = {
    "DO_SET_MODE GUIDED before a position": "the lock-step vehicle knows its position from its first step",
    "default streams: rates": "the lock-step vehicle sends its telemetry once per step, when the back-seat's "
    "set-point for the step arrives, not at ArduSub's rates",
    "GUIDED velocity target: speed": "the lock-step vehicle steps only on a velocity-and-yaw set-point (mask 2503) "
    "naming its current step: its clock is the back-seat's",
    "GUIDED velocity target: timeout": "the lock-step vehicle's clock stands still without the back-seat's "
    "set-points; its failsafe (no set-point for 5 wall s) surfaces it",
}


def allowed(flavour: str) -> dict[str, str]:
    """The rows ``flavour`` may differ in, with their reasons."""
    return ALLOWED | (ALLOWED_LOCKSTEP if flavour == "lockstep" else {})


#: Parameters our front-seat sets from its mission, compared in rows of their own.
MISSION_SET = ("WPNAV_SPEED", "BATT_CAPACITY")
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
_KEPT = {name for name, _, _ in ARDUSUB_PARAMETERS}


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
    return not (kind == "PARAM_VALUE" and (msg.param_id not in _KEPT or msg.param_id.startswith("STAT_")))


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


@dataclass(frozen=True)
class Step:
    """One request and the row(s) its answers fill."""

    row: str
    send: Callable[[Client], None]
    #: what to watch: "answers" (replies to the request) or a streamed message type read after it
    watch: str = "answers"
    #: sent in the first vehicle seconds after boot, before the EKF has a position
    early: bool = False
    #: a multi-message exchange that fills rows of its own (``row`` is their common prefix)
    exchange: Callable[[Client, float], dict[str, list[str]]] | None = None


def _param_set(name: str, value: float, kind: int = mav.MAV_PARAM_TYPE_REAL32) -> Callable[[Client], None]:
    return lambda c: c.conn.mav.param_set_send(1, 1, name.encode(), value, kind)


def _param_read(name: str = "", index: int = -1) -> Callable[[Client], None]:
    return lambda c: c.conn.mav.param_request_read_send(1, 1, name.encode(), index)


def _ftp(seq: int, opcode: int, path: bytes = b"") -> Callable[[Client], None]:
    """An FTP request; ``seq`` differs from the last one (ArduPilot answers a repeated one with its last reply)."""

    def send(c: Client) -> None:
        payload = bytearray(251)
        payload[0:2], payload[3], payload[4] = seq.to_bytes(2, "little"), opcode, len(path)
        payload[12 : 12 + len(path)] = path
        c.conn.mav.file_transfer_protocol_send(0, 1, 1, list(payload))

    return send


def _nothing(c: Client) -> None:
    pass


# -- exchanges of many messages: default streams, the mission protocol, GUIDED velocity ------
#: Vehicle seconds over which the default streams are counted.
STREAM_WINDOW_S = 10.0
#: Streamed messages a back-seat reads; their default rates must agree within a factor of 2.
RELIED_ON = (
    "HEARTBEAT",
    "SYS_STATUS",
    "GPS_RAW_INT",
    "GLOBAL_POSITION_INT",
    "LOCAL_POSITION_NED",
    "ATTITUDE",
    "VFR_HUD",
    "SYSTEM_TIME",
    "BATTERY_STATUS",
    "EKF_STATUS_REPORT",
    "MISSION_CURRENT",
)
#: Rows of "NAME RATE Hz" entries: they match when they name the same messages at rates within this factor.
RATE_ROWS = frozenset({"default streams: rates"})
RATE_FACTOR = 2.0


def _default_streams(client: Client, window: float) -> dict[str, list[str]]:
    """What the vehicle streams unasked: every message type, and the rates (per vehicle second) of those relied on.

    Rates are counted against the vehicle's clock (ATTITUDE's ``time_boot_ms``), so a speed-up
    does not change them; a clock that stands still for a wall second (lock-step) ends the count.
    """
    counts: dict[str, int] = {}
    first = last = None
    ticked = time.monotonic()
    while time.monotonic() - ticked < 1.0 and (first is None or last - first < STREAM_WINDOW_S * 1000):
        msg = client.conn.recv_match(blocking=True, timeout=0.05)
        if msg is None or msg.get_type() == "BAD_DATA":
            continue
        if msg.get_type() == "ATTITUDE":  # the vehicle's clock, 10 Hz
            if last is None or msg.time_boot_ms > last:
                ticked = time.monotonic()
            first = msg.time_boot_ms if first is None else first
            last = msg.time_boot_ms
        if first is not None and not is_answer(msg):
            counts[msg.get_type()] = counts.get(msg.get_type(), 0) + 1
    span = 0.0 if first is None or last is None else (last - first) / 1000
    rates = [f"{name} {counts[name] / span:.2g} Hz" for name in RELIED_ON if name in counts and span > 0]
    return {"default streams: message types": sorted(counts), "default streams: rates": rates}


def rates_agree(ardusub: list[str], ours: list[str], factor: float = RATE_FACTOR) -> bool:
    """Whether two rate rows name the same messages, each at a rate within ``factor`` of the other."""

    def parse(row: list[str]) -> dict[str, float]:
        return {name: float(hz) for name, hz, _ in (entry.split() for entry in row)}

    try:
        a, b = parse(ardusub), parse(ours)
    except ValueError:  # not a rate row ("(row missing)")
        return False
    return a.keys() == b.keys() and all(1 / factor <= b[k] / a[k] <= factor for k in a if a[k] > 0)


#: The mission uploaded: a placeholder for home (item 0, 0.001 deg north of home) and two
#: waypoints 5 m deep north-east of home (frame, degrees of latitude and longitude from home, z).
MISSION_ITEMS = (
    (mav.MAV_FRAME_GLOBAL, 0.001, 0.0, 0.0),
    (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0.0002, 0.0001, -5.0),
    (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0.0004, 0.0003, -5.0),
)


def _mission(client: Client, window: float) -> dict[str, list[str]]:
    """Upload a three-item mission (MISSION_COUNT, the vehicle asks for each item), then read it back."""
    client.drain()
    client.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_HOME_POSITION)
    home = client.wait_for("HOME_POSITION")
    lat0, lon0 = home.latitude / 1e7, home.longitude / 1e7
    sent = [(frame, int(round((lat0 + dlat) * 1e7)), int(round((lon0 + dlon) * 1e7)), z)
            for frame, dlat, dlon, z in MISSION_ITEMS]  # fmt: skip
    client.drain()
    client.conn.mav.mission_count_send(1, 1, len(sent), mav.MAV_MISSION_TYPE_MISSION)
    upload: list[str] = []
    deadline, done = time.monotonic() + max(window, 1.0) * 10, None
    while time.monotonic() < (deadline if done is None else min(deadline, done + client.grace_s)):
        msg = client.conn.recv_match(
            type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK", "STATUSTEXT"], blocking=True, timeout=0.02
        )
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "STATUSTEXT":
            if not SPONTANEOUS.match(msg.text):
                upload.append(canonical(msg))
            continue
        if kind == "MISSION_ACK":
            upload.append(f"MISSION_ACK type={msg.type} mission_type={msg.mission_type}")
            done = time.monotonic()
            continue
        entry = f"{kind} seq={msg.seq} mission_type={msg.mission_type}"
        if not upload or upload[-1] != entry:  # a re-ask of the same item is not an answer of its own
            upload.append(entry)
        if 0 <= msg.seq < len(sent):
            frame, lat, lon, z = sent[msg.seq]
            client.conn.mav.mission_item_int_send(
                1, 1, msg.seq, frame, mav.MAV_CMD_NAV_WAYPOINT, int(msg.seq == 0), 1, 0, 2.0, 0, 0, lat, lon, z,
                mav.MAV_MISSION_TYPE_MISSION,
            )  # fmt: skip
    client.drain()
    client.conn.mav.mission_request_list_send(1, 1, mav.MAV_MISSION_TYPE_MISSION)
    count = client.wait_for("MISSION_COUNT")
    download = [f"MISSION_COUNT count={count.count} mission_type={count.mission_type}"]
    for seq in range(count.count):
        client.conn.mav.mission_request_int_send(1, 1, seq, mav.MAV_MISSION_TYPE_MISSION)
        item = client.wait_for("MISSION_ITEM_INT", ok=lambda m, seq=seq: m.seq == seq)
        download.append(_mission_item(item, sent, (home.latitude, home.longitude)))
    client.conn.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, mav.MAV_MISSION_TYPE_MISSION)
    return {"mission upload": upload, "mission download": download}


def _mission_item(item, sent: list, home: tuple[int, int]) -> str:
    """A MISSION_ITEM_INT read back: its fields, and where it is (as uploaded, home, elsewhere)."""
    at = "elsewhere"
    if item.seq < len(sent) and (item.x, item.y) == tuple(sent[item.seq][1:3]):
        at = "as uploaded"
    elif abs(item.x - home[0]) <= 1 and abs(item.y - home[1]) <= 1:
        at = "at HOME_POSITION"
    z = "" if item.seq == 0 else f" z={item.z:g}"  # home's altitude is where the vehicle booted
    return (
        f"MISSION_ITEM_INT seq={item.seq} frame={item.frame} command={item.command} current={item.current} "
        f"autocontinue={item.autocontinue} params={item.param1:g},{item.param2:g},{item.param3:g},{item.param4:g}"
        f"{z} {at}"
    )


#: The GUIDED velocity target: 1 m/s north, velocity only (position, acceleration, yaw and yaw rate ignored).
VELOCITY_ONLY_MASK = 0b110111000111
TARGET_MS = 1.0
#: Vehicle seconds the target is sent for (every REFRESH_S), then watched after the last one.
FLY_S, REFRESH_S, WATCH_S = 8.0, 0.5, 8.0
#: ArduSub zeroes a velocity target this many vehicle seconds after the last one (GUIDED_POSVEL_TIMEOUT_MS).
TIMEOUT_S = 3.0


def _guided_velocity(client: Client, window: float) -> dict[str, list[str]]:
    """Fly a velocity target in GUIDED (armed), stop sending it and watch the vehicle after the timeout."""
    answers: list[str] = []
    targets: set[str] = set()
    speeds: list[tuple[float, float, float]] = []  # (vehicle s since the first target, north m/s, east m/s)
    now = start = last_sent = None
    ticked = time.monotonic()
    while time.monotonic() - ticked < 1.0:  # a vehicle whose clock stands still (lock-step) is left after 1 s
        if now is not None and start is not None and now - start > FLY_S + WATCH_S:
            break
        if (
            now is not None
            and (start is None or now - start < FLY_S)
            and (last_sent is None or now - last_sent >= REFRESH_S)
        ):
            client.conn.mav.set_position_target_local_ned_send(
                int(now * 1000), 1, 1, mav.MAV_FRAME_LOCAL_NED, VELOCITY_ONLY_MASK, 0, 0, 0, TARGET_MS, 0, 0, 0, 0, 0, 0, 0
            )  # fmt: skip
            start = now if start is None else start
            last_sent = now
        msg = client.conn.recv_match(blocking=True, timeout=0.02)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "GLOBAL_POSITION_INT":
            if now is None or msg.time_boot_ms / 1000 > now:
                ticked = time.monotonic()
            now = msg.time_boot_ms / 1000
            if start is not None:
                speeds.append((now - start, msg.vx / 100, msg.vy / 100))
        elif kind in ("POSITION_TARGET_LOCAL_NED", "POSITION_TARGET_GLOBAL_INT"):
            targets.add(f"{kind} frame={msg.coordinate_frame} type_mask={msg.type_mask}")
        elif is_answer(msg):
            answers.append(canonical(msg))
    rows = {
        "GUIDED velocity target: answers": answers,
        "GUIDED velocity target: POSITION_TARGET streamed": sorted(targets),
    }
    return rows | _timeout_rows(speeds, 0.0 if start is None or last_sent is None else last_sent - start)


def _timeout_rows(speeds: list[tuple[float, float, float]], stop: float) -> dict[str, list[str]]:
    """What the vehicle did with the target (``speeds`` as sampled, the last target sent ``stop`` s in)."""
    reached = max((vn for t, vn, _ in speeds if t <= stop), default=0.0)
    after = [(t - stop, math.hypot(vn, ve)) for t, vn, ve in speeds if t > stop]
    held = max((v for t, v in after if t <= 0.5), default=0.0)  # the speed when the last target went out
    slowing = next((t for t, v in after if v < 0.9 * held), None) if held > 0 else None
    braked = slowing is not None and any(v < 0.5 * held for t, v in after if t <= slowing + 1.0)
    early, late = TIMEOUT_S - 0.5, TIMEOUT_S + 1.5  # the last target's delivery and a 3 Hz report's spacing
    return {
        "GUIDED velocity target: speed": [f"north speed reached >= {TARGET_MS / 2:g} m/s: {reached >= TARGET_MS / 2}"],
        "GUIDED velocity target: timeout": [
            f"starts slowing {early:g}-{late:g} s after the last target: {slowing is not None and early <= slowing <= late}"
        ],
        "GUIDED velocity target: braking": [
            f"below half the speed within 1 s of slowing: {braked}",
            f"below 0.1 m/s {WATCH_S:g} s after the last target: {bool(after) and after[-1][1] < 0.1}",
        ],
    }


C = mav
STEPS: tuple[Step, ...] = (
    # the firmware's first seconds: only what does not depend on where in its boot timeline they fall
    Step("DO_SET_MODE GUIDED before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 4), early=True),
    Step("DO_SET_MODE MANUAL before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 19), early=True),
    Step("HEARTBEAT on connect", _nothing, "HEARTBEAT"),
    Step("SYS_STATUS sensor bits", _nothing, "SYS_STATUS"),
    Step("EKF_STATUS_REPORT with a position", _nothing, "EKF_STATUS_REPORT"),
    Step("default streams", _nothing, exchange=_default_streams),
    Step("PARAM_REQUEST_LIST", lambda c: c.conn.mav.param_request_list_send(1, 1), "params"),
    Step("AUTOPILOT_VERSION (REQUEST_MESSAGE)", lambda c: c.command(C.MAV_CMD_REQUEST_MESSAGE, 148)),
    Step("AUTOPILOT_VERSION (REQUEST_AUTOPILOT_CAPABILITIES)", lambda c: c.command(520, 1)),
    Step("HOME_POSITION (REQUEST_MESSAGE)", lambda c: c.command(C.MAV_CMD_REQUEST_MESSAGE, 242)),
    Step("REQUEST_MESSAGE unknown id", lambda c: c.command(C.MAV_CMD_REQUEST_MESSAGE, 12345)),
    Step("PARAM_REQUEST_READ by name", _param_read("FS_GCS_TIMEOUT")),
    Step("PARAM_REQUEST_READ by index", _param_read(index=0)),
    Step("PARAM_REQUEST_READ index out of range", _param_read(index=30000)),
    Step("PARAM_REQUEST_READ unknown name", _param_read("NO_SUCH_PARAM")),
    Step("PARAM_SET unknown name", _param_set("NO_SUCH_PARAM", 1.0)),
    Step("PARAM_SET NaN", _param_set("WPNAV_ACCEL", math.nan)),
    Step("PARAM_SET infinity", _param_set("WPNAV_ACCEL", math.inf)),
    Step("read back after NaN and infinity", _param_read("WPNAV_ACCEL")),
    Step("PARAM_SET float", _param_set("WPNAV_ACCEL", 200.0)),
    Step("read back after PARAM_SET", _param_read("WPNAV_ACCEL")),
    Step("PARAM_SET far out of range", _param_set("FS_GCS_TIMEOUT", 1e6)),
    Step("PARAM_SET back in range", _param_set("FS_GCS_TIMEOUT", 5.0)),
    Step("PARAM_SET INT8 overflow", _param_set("FS_GCS_ENABLE", 1000.0, C.MAV_PARAM_TYPE_INT8)),
    Step("PARAM_SET INT8 back", _param_set("FS_GCS_ENABLE", 2.0, C.MAV_PARAM_TYPE_INT8)),
    Step("PARAM_SET INT8 fraction", _param_set("FRAME_CONFIG", 1.7, C.MAV_PARAM_TYPE_INT8)),
    Step("REQUEST_DATA_STREAM POSITION 1 Hz", lambda c: c.conn.mav.request_data_stream_send(1, 1, 6, 1, 1)),
    Step("MAV1_POSITION after REQUEST_DATA_STREAM", _param_read("MAV1_POSITION")),
    Step("REQUEST_DATA_STREAM POSITION back to 3 Hz", lambda c: c.conn.mav.request_data_stream_send(1, 1, 6, 3, 1)),
    Step("SET_MESSAGE_INTERVAL ATTITUDE 1 s", lambda c: c.command(C.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 1e6)),
    Step("GET_MESSAGE_INTERVAL ATTITUDE", lambda c: c.command(C.MAV_CMD_GET_MESSAGE_INTERVAL, 30)),
    Step("SET_MESSAGE_INTERVAL ATTITUDE default", lambda c: c.command(C.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 0)),
    Step("SET_MESSAGE_INTERVAL unknown id", lambda c: c.command(C.MAV_CMD_SET_MESSAGE_INTERVAL, 330, 1e6)),
    Step("DO_SET_MODE unknown mode 15", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 15)),
    Step("SET_MODE unknown mode 15", lambda c: c.conn.mav.set_mode_send(1, 1, 15)),
    Step("DO_SET_MODE without CUSTOM_MODE flag", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 0, 2)),
    Step("DO_SET_MODE ALT_HOLD", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 2)),
    Step("HEARTBEAT in ALT_HOLD", _nothing, "HEARTBEAT"),
    Step("SET_MODE MANUAL", lambda c: c.conn.mav.set_mode_send(1, 1, 19)),
    Step("HEARTBEAT in MANUAL", _nothing, "HEARTBEAT"),
    Step("DO_SET_MODE GUIDED", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 4)),
    Step("HEARTBEAT in GUIDED", _nothing, "HEARTBEAT"),
    Step("SYS_STATUS in GUIDED", _nothing, "SYS_STATUS"),
    Step("arm", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 1)),
    Step("HEARTBEAT armed", _nothing, "HEARTBEAT"),
    Step("GUIDED velocity target", _nothing, exchange=_guided_velocity),
    Step("arm when armed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 1)),
    Step("disarm", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("disarm when disarmed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("arm with param1 2", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 2)),
    Step("unsupported command", lambda c: c.command(31000)),
    Step("FTP reset sessions", _ftp(10, 2)),
    Step("FTP open @PARAM/param.pck", _ftp(11, 4, b"@PARAM/param.pck")),
    Step("mission", _nothing, exchange=_mission),
)


def run(client: Client, window: float, expected: dict[str, list[str]] | None = None) -> dict[str, list[str]]:
    """Every step's rows: row name -> canonical answers in the order they came."""
    rows: dict[str, list[str]] = {}
    positioned = False
    for step in STEPS:
        if not step.early and not positioned:
            client.wait_for("EKF_STATUS_REPORT", timeout=60, ok=lambda m: m.flags & 0x18 == 0x18)  # a position
            positioned = True
        client.drain()
        step.send(client)
        if step.exchange is not None:
            rows.update(step.exchange(client, window))
        elif step.watch == "params":
            rows.update(_param_rows(client, window))
        elif step.watch != "answers":
            rows[step.row] = [canonical(client.wait_for(step.watch))]
        else:
            expect = None if expected is None else len(expected.get(step.row, []))
            answers = [canonical(m) for m in client.answers(expect or None, window)]
            if step.early:  # home, origin and parameters the boot sets come when they come: only the answer counts
                answers = [a for a in answers if a.startswith(("COMMAND_ACK", "STATUSTEXT"))]
            rows[step.row] = answers
    return rows


def _param_rows(client: Client, window: float) -> dict[str, list[str]]:
    """The parameter list's rows: its banner, its shape and the boot values of the parameters we keep."""
    banner, values, indices, count = [], {}, set(), None
    deadline = time.monotonic() + max(window, 1.0) * 10
    while time.monotonic() < deadline and (count is None or len(indices) < count):
        msg = client.conn.recv_match(type=["STATUSTEXT", "PARAM_VALUE"], blocking=True, timeout=0.05)
        if msg is None:
            continue
        if msg.get_type() == "STATUSTEXT":
            if not SPONTANEOUS.match(msg.text):
                banner.append(canonical(msg))
        elif msg.param_index != 65535:
            count = msg.param_count
            indices.add(msg.param_index)
            if msg.param_id in _KEPT:
                values[msg.param_id] = f"{msg.param_id}={msg.param_value:g} type={msg.param_type}"
    shape = f"{len(indices)} PARAM_VALUE, indices 0..{count - 1 if count else '?'}, param_count {count}"
    rows = {"PARAM_REQUEST_LIST banner": banner, "PARAM_REQUEST_LIST": [shape]}
    rows["boot values"] = [v for name, v in sorted(values.items()) if name not in MISSION_SET]
    for name in MISSION_SET:
        rows[f"boot {name}"] = [values.get(name, "missing")]
    return rows


@dataclass(frozen=True)
class Row:
    name: str
    ardusub: list[str]
    ours: list[str]

    @property
    def matches(self) -> bool:
        if self.name in RATE_ROWS:
            return rates_agree(self.ardusub, self.ours)
        return self.ardusub == self.ours

    #: why this row may differ, if it may
    reason: str | None = None

    @property
    def verdict(self) -> str:
        if self.matches:
            return "match"
        return f"differs: {self.reason}" if self.reason else "DIFFERS (no reason on the allow-list)"

    @property
    def allowed(self) -> bool:
        return self.matches or self.reason is not None


def compare(ardusub: dict[str, list[str]], ours: dict[str, list[str]], flavour: str = "bare") -> list[Row]:
    reasons = allowed(flavour)
    return [Row(name, ardusub[name], ours.get(name, ["(row missing)"]), reasons.get(name)) for name in ardusub]


def table(rows: list[Row], title: str) -> str:
    def cell(answers: list[str]) -> str:
        if len(answers) > 3:
            return f"{answers[0]} ... ({len(answers)} answers)"
        return "; ".join(answers) or "(no answer)"

    lines = [f"## {title}", "| row | ArduSub | ours | verdict |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.name} | {cell(r.ardusub)} | {cell(r.ours)} | {r.verdict} |")
    for r in rows:
        if not r.matches and (len(r.ardusub) > 3 or len(r.ours) > 3) and r.name != "boot values":
            lines.append(f"{r.name}: ArduSub {r.ardusub}; ours {r.ours}")
    matched = sum(r.matches for r in rows)
    lines.append(f"{matched} of {len(rows)} rows match; {sum(r.allowed for r in rows) - matched} differ with a reason")
    return "\n".join(lines)


# -- the two sides ------------------------------------------------------------------------
def load_fixture() -> dict:
    return json.loads(FIXTURE.read_text())


@contextmanager
def ardusub_sitl(speedup: float = 10.0) -> Iterator[Client]:
    """A client of a fresh ArduSub SITL ($ARDUSUB_SITL) at range2017's launch point."""
    from planner.fly.ardusub_sitl import ArduSubSitl, launch_point
    from sim.uuv import load_mission

    home = launch_point(load_mission(Path(__file__).parents[4] / "examples" / "range2017.toml"))
    with ArduSubSitl(home, speedup=speedup) as sitl:  # positions are not compared
        client = Client(sitl.connection, grace_s=0.3)
        try:
            client.hello()
            yield client
        finally:
            client.close()


@contextmanager
def front_seat(flavour: str) -> Iterator[Client]:
    """A client of our front-seat (``lockstep`` or ``bare``) serving in a thread; all closed on exit."""
    from sim.uuv.ardusub.frontseat import FrontSeat
    from tests.support.uuvworld import mission

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    bare = flavour == "bare"
    fs = FrontSeat(mission(), [0.5], f"udpin:127.0.0.1:{port}", bare=bare, speedup=20.0, ekf_ready_s=20.0)
    thread = threading.Thread(target=fs.serve, name=f"frontseat-{flavour}", daemon=True)
    thread.start()
    client = Client(f"udpout:127.0.0.1:{port}", grace_s=0.05)
    try:
        client.hello(timeout=5)
        yield client
    finally:
        client.close()
        fs.stop()
        thread.join(timeout=5)
        fs.close()


def ours(flavour: str, expected: dict[str, list[str]]) -> dict[str, list[str]]:
    with front_seat(flavour) as client:
        return run(client, window=0.3, expected=expected)


def record() -> dict:
    with ardusub_sitl() as client:
        rows = run(client, window=0.8)
    return {"firmware": FIRMWARE, "recorded_with": "tests/sim/uuv/ardusub/conformance.py --record", "rows": rows}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sitl", action="store_true", help="also run the sequences live against $ARDUSUB_SITL")
    parser.add_argument("--record", action="store_true", help="record ArduSub's answers into the fixture")
    parser.add_argument("--flavour", choices=FLAVOURS, action="append", help="front-seat flavour(s) to check")
    args = parser.parse_args(argv)
    if args.record:
        fixture = record()
        FIXTURE.write_text(json.dumps(fixture, indent=1) + "\n")
        print(f"recorded {len(fixture['rows'])} rows from {fixture['firmware']} into {FIXTURE}")
    fixture = load_fixture()
    if args.sitl and not args.record:
        with ardusub_sitl() as client:
            live = run(client, window=0.8, expected=fixture["rows"])
        print(table(compare(fixture["rows"], live), f"live ArduSub SITL vs the recording ({fixture['firmware']})"))
    ok = True
    for flavour in args.flavour or FLAVOURS:
        rows = compare(fixture["rows"], ours(flavour, fixture["rows"]), flavour)
        print(table(rows, f"{flavour} front-seat vs {fixture['firmware']}"))
        ok &= all(r.allowed for r in rows)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
