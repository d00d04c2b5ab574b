"""Does the simulated front-seat answer a ground station as ArduSub does?  Message by message.

The sequences a ground station sends on connect and in use (heartbeat watch, AUTOPILOT_VERSION,
the parameter list, reads and sets including bad ones, mode changes valid and invalid,
arm/disarm, an unsupported command, stream rates, MAVLink FTP) go over real MAVLink on
loopback, first to ArduSub SITL (the firmware is the reference), then to
:class:`sim.uuv.frontseat.FrontSeat` in both flavours; each answer is reduced to the
fields that matter (:func:`canonical`) and the two are compared row by row.  A row matches
or carries a reason from :data:`ALLOWED`; anything else fails ``test_conformance.py``.

ArduSub's answers are recorded once into ``ardusub_answers.json`` next to this module (with the
firmware version), so the test needs no firmware::

    python -m tests.sim.uuv.conformance                # ours (both flavours) against the recording
    python -m tests.sim.uuv.conformance --sitl         # ... and live against ArduSub SITL ($ARDUSUB_SITL)
    python -m tests.sim.uuv.conformance --record       # record ArduSub's answers into the fixture

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

from sim.uuv.params import ARDUSUB_PARAMETERS, FIRMWARE  # noqa: E402

mav = mavutil.mavlink

FIXTURE = Path(__file__).with_name("ardusub_answers.json")
#: range2017's launch point: SITL's home (the front-seat's comes from its mission; positions are not compared).
HOME = (47.6953287, -122.6264071, 0.0, 0.0)
FLAVOURS = ("lockstep", "bare")

#: Rows allowed to differ, and why (the conformance table prints the reason).
ALLOWED: dict[str, str] = {
    "PARAM_REQUEST_LIST": "a subset of ArduSub's 1,386: those a ground station reads on connect and our model maps to",
    "PARAM_REQUEST_LIST banner": "line 2 is the board's unique id; ours names the simulator",
    "FTP open @PARAM/param.pck": "the banner after it: line 2 is the board's unique id; ours names the simulator",
    "boot WPNAV_SPEED": "set from the mission's cruise speed: our vehicle is not a BlueROV2",
    "boot BATT_CAPACITY": "set from the mission's battery (Wh at 14.8 V)",
}
#: Rows only the lock-step flavour may differ in, and why.
ALLOWED_LOCKSTEP: dict[str, str] = {
    "DO_SET_MODE GUIDED before a position": "the lock-step vehicle knows its position from its first step",
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
            if msg is None or msg.get_type() not in ANSWERS:
                continue
            if msg.get_type() == "STATUSTEXT" and SPONTANEOUS.match(msg.text):
                continue
            if msg.get_type() == "PARAM_VALUE" and (msg.param_id not in _KEPT or msg.param_id.startswith("STAT_")):
                continue  # the firmware's own statistics, and what it saves on disarming
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


C = mav
STEPS: tuple[Step, ...] = (
    # the firmware's first seconds: only what does not depend on where in its boot timeline they fall
    Step("DO_SET_MODE GUIDED before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 4), early=True),
    Step("DO_SET_MODE MANUAL before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 19), early=True),
    Step("HEARTBEAT on connect", _nothing, "HEARTBEAT"),
    Step("SYS_STATUS sensor bits", _nothing, "SYS_STATUS"),
    Step("EKF_STATUS_REPORT with a position", _nothing, "EKF_STATUS_REPORT"),
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
    Step("arm when armed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 1)),
    Step("disarm", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("disarm when disarmed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("arm with param1 2", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 2)),
    Step("unsupported command", lambda c: c.command(31000)),
    Step("FTP reset sessions", _ftp(10, 2)),
    Step("FTP open @PARAM/param.pck", _ftp(11, 4, b"@PARAM/param.pck")),
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
        if step.watch == "params":
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
    from planner.ardusub_sitl import ArduSubSitl

    with ArduSubSitl(HOME, speedup=speedup) as sitl:
        client = Client(sitl.connection, grace_s=0.3)
        try:
            client.hello()
            yield client
        finally:
            client.close()


@contextmanager
def front_seat(flavour: str) -> Iterator[Client]:
    """A client of our front-seat (``lockstep`` or ``bare``) serving in a thread; all closed on exit."""
    from sim.uuv.frontseat import FrontSeat
    from tests.sim.uuv.uuvworld import mission

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
    return {"firmware": FIRMWARE, "recorded_with": "tests/sim/uuv/conformance.py --record", "rows": rows}


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
