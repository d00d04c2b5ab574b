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

from sim.uuv.ardusub.params import FIRMWARE  # noqa: E402
from tests.sim.uuv.ardusub.exchanges import default_streams, guided_velocity, mission_protocol  # noqa: E402
from tests.sim.uuv.ardusub.ground_station import KEPT, SPONTANEOUS, Client, canonical  # noqa: E402

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


#: Rows of "NAME RATE Hz" entries: they match when they name the same messages at rates within this factor.
RATE_ROWS = frozenset({"default streams: rates"})
RATE_FACTOR = 2.0


def rates_agree(ardusub: list[str], ours: list[str], factor: float = RATE_FACTOR) -> bool:
    """Whether two rate rows name the same messages, each at a rate within ``factor`` of the other."""

    def parse(row: list[str]) -> dict[str, float]:
        return {name: float(hz) for name, hz, _ in (entry.split() for entry in row)}

    try:
        a, b = parse(ardusub), parse(ours)
    except ValueError:  # not a rate row ("(row missing)")
        return False
    return a.keys() == b.keys() and all(1 / factor <= b[k] / a[k] <= factor for k in a if a[k] > 0)


C = mav
STEPS: tuple[Step, ...] = (
    # the firmware's first seconds: only what does not depend on where in its boot timeline they fall
    Step("DO_SET_MODE GUIDED before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 4), early=True),
    Step("DO_SET_MODE MANUAL before a position", lambda c: c.command(C.MAV_CMD_DO_SET_MODE, 1, 19), early=True),
    Step("HEARTBEAT on connect", _nothing, "HEARTBEAT"),
    Step("SYS_STATUS sensor bits", _nothing, "SYS_STATUS"),
    Step("EKF_STATUS_REPORT with a position", _nothing, "EKF_STATUS_REPORT"),
    Step("default streams", _nothing, exchange=default_streams),
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
    Step("GUIDED velocity target", _nothing, exchange=guided_velocity),
    Step("arm when armed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 1)),
    Step("disarm", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("disarm when disarmed", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 0)),
    Step("arm with param1 2", lambda c: c.command(C.MAV_CMD_COMPONENT_ARM_DISARM, 2)),
    Step("unsupported command", lambda c: c.command(31000)),
    Step("FTP reset sessions", _ftp(10, 2)),
    Step("FTP open @PARAM/param.pck", _ftp(11, 4, b"@PARAM/param.pck")),
    Step("mission", _nothing, exchange=mission_protocol),
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
            if msg.param_id in KEPT:
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
    # the firmware as it ships (scripting off): the recording's vehicle; positions are not compared
    with ArduSubSitl(home, speedup=speedup, parameters={"SCR_ENABLE": 0}) as sitl:
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
