"""What an operator's bring-up asks of the bridge: latest messages, COMMAND_LONG, stream rates, mission upload.

Over real loopback MAVLink and a real Zenoh session: against the simulated front-seat
(:class:`sim.uuv.ardusub.frontseat.FrontSeat`) where it shows the behaviour, and against a small scripted
pymavlink vehicle where it cannot (a vehicle that NACKs, stalls, answers IN_PROGRESS or nothing).
"""

from __future__ import annotations

import contextlib
import math
import os
import select
import socket
import threading
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

import sim.uuv  # noqa: E402
from bridge.frames import mavlink2  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.mission_upload import MissionItem  # noqa: E402
from bridge.session import open_session  # noqa: E402
from rapt.errors import InputError, LinkError, LinkTimeoutError, RefusedError, RunError  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from tests.support.bridge_rig import rig  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402

pytestmark = [pytest.mark.integration]

M = mavlink2
EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
HOME = (47.6953287, -122.6264071)
USER_1 = M.MAV_CMD_USER_1  # a command no vehicle acts on: free for scripted answers


def three_items() -> list[MissionItem]:
    """Home, then two waypoints at 2 m and 3 m depth (z up-positive in the relative-altitude frame)."""
    lat, lon = HOME
    return [
        MissionItem.waypoint(0, lat, lon, 0.0),
        MissionItem.waypoint(1, lat + 2e-4, lon, -2.0),
        MissionItem.waypoint(2, lat + 2e-4, lon + 3e-4, -3.0, hold_s=5.0),
    ]


class ScriptedVehicle:
    """An autopilot (sysid 1, compid 1, ArduSub HEARTBEAT at 20 Hz) that answers what it receives with
    ``script(vehicle, msg) -> [(delay_s, message), ...]``; records everything it receives."""

    def __init__(self, device: str, script=None):
        self.conn = mavutil.mavlink_connection(device, source_system=1, source_component=1, dialect="ardupilotmega")
        self.script = script or (lambda vehicle, msg: [])
        self.received: list = []
        self.state: dict = {}
        self._due: list[tuple[float, object]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="scripted-vehicle", daemon=True)
        self._thread.start()

    def messages(self, name: str) -> list:
        with self._lock:
            return [m for m in self.received if m.get_type() == name]

    def write(self, frame: bytes) -> None:
        with self._lock:
            self.conn.write(frame)

    def _send_due(self, now: float) -> None:
        with self._lock:
            due = [m for t, m in self._due if t <= now]
            self._due = [(t, m) for t, m in self._due if t > now]
            for msg in due:
                self.conn.mav.send(msg)

    def _loop(self) -> None:
        next_beat = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_beat:
                hb = M.MAVLink_heartbeat_message(
                    M.MAV_TYPE_SUBMARINE, M.MAV_AUTOPILOT_ARDUPILOTMEGA, M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 19, 3, 3
                )
                with self._lock:
                    self.conn.mav.send(hb)
                next_beat = now + 0.05
            self._send_due(now)
            if not select.select([self.conn.fd], [], [], 0.005)[0]:
                continue
            while (msg := self.conn.recv_msg()) is not None:
                if msg.get_type() == "BAD_DATA":
                    continue
                with self._lock:
                    self.received.append(msg)
                replies = self.script(self, msg)
                with self._lock:
                    self._due += [(time.monotonic() + delay, reply) for delay, reply in replies]

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.conn.close()


def ack(command: int, result: int, progress: int = 0, target=(1, 191)):
    return M.MAVLink_command_ack_message(command, result, progress, 0, *target)


def ardupilot_upload(nack_first_item_1: bool = False, legacy: bool = True):
    """The vehicle side of an upload as ArduPilot runs it: MISSION_REQUEST (deprecated) for each item,
    MISSION_ACK at the end; optionally an INVALID_SEQUENCE NACK for item 1 once, then asked again."""
    request = M.MAVLink_mission_request_message if legacy else M.MAVLink_mission_request_int_message

    def script(vehicle, msg):
        s, name = vehicle.state, msg.get_type()
        if name == "MISSION_COUNT":
            s.update(count=msg.count, items=[])
            return [(0, request(1, 191, 0, 0))]
        if name == "MISSION_ITEM_INT":
            if msg.seq == 1 and nack_first_item_1 and not s.get("nacked"):
                s["nacked"] = True
                return [(0, M.MAVLink_mission_ack_message(1, 191, M.MAV_MISSION_INVALID_SEQUENCE, 0)),
                        (0.05, request(1, 191, 1, 0))]  # fmt: skip
            if msg.seq != len(s["items"]):
                return [(0, M.MAVLink_mission_ack_message(1, 191, M.MAV_MISSION_INVALID_SEQUENCE, 0))]
            s["items"].append(msg)
            if len(s["items"]) == s["count"]:
                return [(0, M.MAVLink_mission_ack_message(1, 191, M.MAV_MISSION_ACCEPTED, 0))]
            return [(0, request(1, 191, len(s["items"]), 0))]
        return []

    return script


@contextlib.contextmanager
def link(script=None, **bridge_kw):
    """Scripted vehicle on udpout -> bridge on udpin with a loopback Zenoh hub; all closed afterwards."""
    port = free_port(socket.SOCK_DGRAM)
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
    bridge = MavlinkBridge(
        f"udpin:127.0.0.1:{port}", session, heartbeat_hz=20.0, **{"allow_commands": True, **bridge_kw}
    )
    vehicle = None
    try:
        bridge.start()
        vehicle = ScriptedVehicle(f"udpout:127.0.0.1:{port}", script)
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        yield bridge, vehicle
    finally:
        if vehicle is not None:
            vehicle.close()
        bridge.close()
        session.close()


# --------------------------------------------------------------------------- latest messages
def test_latest_messages_and_the_autopilot_heartbeat_from_the_autopilot_only():
    with link(silence_s=0.3) as (bridge, vehicle):
        hb = bridge.autopilot
        assert hb is not None and (hb.type, hb.autopilot, hb.custom_mode, hb.system_status) == (12, 3, 19, 3)
        assert hb.mode == "MANUAL" and not hb.armed and hb.monotonic_s <= time.monotonic()
        msg, at = bridge.latest("HEARTBEAT")
        assert msg.type == 12 and at <= time.monotonic()
        assert bridge.latest("SYSTEM_TIME") is None
        vehicle.write(M.MAVLink_system_time_message(7, 8).pack(M.MAVLink(None, 1, 1)))
        vehicle.write(M.MAVLink_system_time_message(99, 99).pack(M.MAVLink(None, 2, 1)))  # another system's
        vehicle.write(M.MAVLink_attitude_message(5, 0.1, 0, 0, 0, 0, 0).pack(M.MAVLink(None, 2, 1)))
        got = wait_until(lambda: bridge.latest("SYSTEM_TIME"), what="SYSTEM_TIME")
        time.sleep(0.1)  # the other system's frames came behind it: give them time to be (not) kept
        assert got[0].time_unix_usec == 7 and bridge.latest("SYSTEM_TIME")[0].time_unix_usec == 7
        assert bridge.latest("ATTITUDE") is None and bridge.latest("NO_SUCH_MESSAGE") is None
        with pytest.raises(InputError, match="^name: "):
            bridge.latest(30)
        vehicle.close()
        wait_until(lambda: not bridge.linked and bridge.stats["link_losses"] == 1, what="the link loss")
        assert bridge.latest("HEARTBEAT") is None and bridge.autopilot is None  # nothing stale


# --------------------------------------------------------------------------- COMMAND_LONG
def test_command_long_waits_through_in_progress_for_the_final_ack_without_sending_again():
    def script(vehicle, msg):
        if msg.get_type() == "COMMAND_LONG" and msg.command == USER_1:
            ip = M.MAV_RESULT_IN_PROGRESS
            return [(0, ack(USER_1, ip, 10)), (0.25, ack(USER_1, ip, 50)), (0.5, ack(USER_1, M.MAV_RESULT_ACCEPTED))]
        return []

    with link(script) as (bridge, vehicle):
        started = time.monotonic()
        assert bridge.command_long(USER_1, (1.5, math.nan), timeout=0.35, retries=3) == M.MAV_RESULT_ACCEPTED
        assert 0.45 < time.monotonic() - started < 2
        (cmd,) = vehicle.messages("COMMAND_LONG")  # IN_PROGRESS stopped the retries
        assert (cmd.target_system, cmd.target_component, cmd.confirmation) == (1, 1, 0)
        assert cmd.param1 == 1.5 and math.isnan(cmd.param2)
        assert (cmd.param3, cmd.param4, cmd.param5, cmd.param6, cmd.param7) == (0, 0, 0, 0, 0)
        assert bridge.latest("COMMAND_ACK")[0].result == M.MAV_RESULT_ACCEPTED


def test_in_progress_then_silence_names_the_progress():
    def script(vehicle, msg):
        if msg.get_type() == "COMMAND_LONG":
            return [(0, ack(msg.command, M.MAV_RESULT_IN_PROGRESS, 40))]
        return []

    with link(script) as (bridge, vehicle):
        with pytest.raises(LinkTimeoutError, match=rf"^command_long: command {USER_1} is IN_PROGRESS \(40% done\)"):
            bridge.command_long(USER_1, timeout=0.2)
        assert len(vehicle.messages("COMMAND_LONG")) == 1
        progress = bridge.latest("COMMAND_ACK")[0]
        assert (progress.result, progress.progress) == (M.MAV_RESULT_IN_PROGRESS, 40)


def test_command_long_tries_again_and_ignores_acks_for_someone_else():
    def script(vehicle, msg):
        if msg.get_type() == "COMMAND_LONG" and msg.confirmation == 2:
            return [(0, ack(msg.command, M.MAV_RESULT_DENIED, target=(9, 191))),  # to another system
                    (0.05, ack(msg.command, M.MAV_RESULT_FAILED))]  # fmt: skip
        return []

    with link(script) as (bridge, vehicle):
        assert bridge.command_long(USER_1, timeout=0.15, retries=2) == M.MAV_RESULT_FAILED
        assert [m.confirmation for m in vehicle.messages("COMMAND_LONG")] == [0, 1, 2]
        with pytest.raises(LinkTimeoutError, match="^command_long: no COMMAND_ACK after 2 tries$"):
            bridge.command_long(M.MAV_CMD_USER_2, timeout=0.1, retries=1)


def test_message_intervals_and_data_streams_reach_the_autopilot():
    def script(vehicle, msg):
        if msg.get_type() == "COMMAND_LONG":
            return [(0, ack(msg.command, M.MAV_RESULT_ACCEPTED))]
        return []

    with link(script) as (bridge, vehicle):
        assert bridge.set_message_interval(M.MAVLINK_MSG_ID_ATTITUDE, 50) == M.MAV_RESULT_ACCEPTED
        assert bridge.set_message_interval(M.MAVLINK_MSG_ID_SYSTEM_TIME, 0) == M.MAV_RESULT_ACCEPTED
        assert bridge.set_message_interval(M.MAVLINK_MSG_ID_GPS_RAW_INT, 0.5) == M.MAV_RESULT_ACCEPTED
        cmds = vehicle.messages("COMMAND_LONG")
        assert {c.command for c in cmds} == {M.MAV_CMD_SET_MESSAGE_INTERVAL}
        assert [(c.param1, c.param2) for c in cmds] == [(30, 20_000), (2, -1), (24, 2_000_000)]
        bridge.request_data_stream(M.MAV_DATA_STREAM_EXTRA1, 4)
        bridge.request_data_stream(M.MAV_DATA_STREAM_ALL, 0, start=False)
        got = wait_until(
            lambda: len(vehicle.messages("REQUEST_DATA_STREAM")) == 2 and vehicle.messages("REQUEST_DATA_STREAM")
        )
        assert [
            (m.target_system, m.target_component, m.req_stream_id, m.req_message_rate, m.start_stop) for m in got
        ] == [
            (1, 1, M.MAV_DATA_STREAM_EXTRA1, 4, 1),
            (1, 1, M.MAV_DATA_STREAM_ALL, 0, 0),
        ]


# --------------------------------------------------------------------------- mission upload
def test_upload_as_ardupilot_runs_it_with_a_nack_on_the_way():
    """Deprecated MISSION_REQUEST answered with MISSION_ITEM_INT; an INVALID_SEQUENCE NACK does not end it."""
    with link(ardupilot_upload(nack_first_item_1=True)) as (bridge, vehicle):
        items = three_items()
        as_message = items[2].to_message(0, 0, 0)  # a pymavlink message is taken as it is
        assert bridge.upload_mission([items[0], items[1], as_message]) == M.MAV_MISSION_ACCEPTED
        (count,) = vehicle.messages("MISSION_COUNT")
        assert (count.target_system, count.target_component, count.count, count.mission_type) == (1, 1, 3, 0)
        stored = vehicle.state["items"]
        assert [MissionItem.from_message(m) for m in stored] == items
        assert all((m.target_system, m.target_component) == (1, 1) for m in stored)
        assert [m.seq for m in vehicle.messages("MISSION_ITEM_INT")] == [0, 1, 1, 2]  # item 1 asked for twice
        # MISSION_REQUEST_INT, and an empty upload (clears the mission)
    with link(ardupilot_upload(legacy=False)) as (bridge, vehicle):
        assert bridge.upload_mission(three_items(), mission_type=M.MAV_MISSION_TYPE_MISSION) == 0
        assert len(vehicle.state["items"]) == 3


def test_a_silent_vehicle_times_out_naming_the_step_after_the_retries():
    with link() as (bridge, vehicle):
        started = time.monotonic()
        with pytest.raises(LinkTimeoutError) as info:
            bridge.upload_mission(three_items(), timeout=0.2, retries=2)
        assert (
            str(info.value) == "upload_mission: MISSION_COUNT: no MISSION_REQUEST for item 0 after 3 tries, 0.2 s each"
        )
        assert 0.55 < time.monotonic() - started < 2
        wait_until(lambda: len(vehicle.messages("MISSION_COUNT")) == 3, what="three MISSION_COUNTs")


def test_a_vehicle_that_stalls_mid_upload_is_asked_again_then_named():
    def script(vehicle, msg):
        if msg.get_type() == "MISSION_COUNT":
            return [(0, M.MAVLink_mission_request_int_message(1, 191, 0, 0))]
        if msg.get_type() == "MISSION_ITEM_INT" and msg.seq == 0 and not vehicle.state.get("asked"):
            vehicle.state["asked"] = True
            return [(0, M.MAVLink_mission_request_int_message(1, 191, 1, 0))]
        return []  # item 1 never acknowledged or followed by a request

    with link(script) as (bridge, vehicle):
        with pytest.raises(
            LinkTimeoutError, match=r"^upload_mission: item 1: no MISSION_REQUEST for item 2 after 2 tries"
        ):
            bridge.upload_mission(three_items(), timeout=0.2, retries=1)
        assert [m.seq for m in vehicle.messages("MISSION_ITEM_INT")] == [0, 1, 1]


def test_a_final_nack_is_the_result():
    def script(vehicle, msg):
        if msg.get_type() == "MISSION_COUNT":
            return [(0, M.MAVLink_mission_request_int_message(1, 191, 0, 0))]
        if msg.get_type() == "MISSION_ITEM_INT":
            return [(0, M.MAVLink_mission_ack_message(1, 191, M.MAV_MISSION_UNSUPPORTED_FRAME, 0))]
        return []

    with link(script) as (bridge, vehicle):
        assert bridge.upload_mission(three_items(), timeout=0.2) == M.MAV_MISSION_UNSUPPORTED_FRAME
        assert len(vehicle.messages("MISSION_ITEM_INT")) == 1


def test_one_upload_at_a_time():
    with link() as (bridge, vehicle):
        errors: list = []

        def first():
            try:
                bridge.upload_mission(three_items(), timeout=0.5, retries=0)
            except LinkTimeoutError as error:
                errors.append(error)

        thread = threading.Thread(target=first)
        thread.start()
        wait_until(lambda: vehicle.messages("MISSION_COUNT"), what="the first upload")
        with pytest.raises(RunError, match="^upload_mission: another upload is running"):
            bridge.upload_mission(three_items())
        thread.join(timeout=5)
        assert len(errors) == 1 and len(vehicle.messages("MISSION_COUNT")) == 1


# --------------------------------------------------------------------------- gates and arguments
def every_new_call(bridge):
    return [
        lambda: bridge.command_long(USER_1),
        lambda: bridge.set_message_interval(30, 10),
        lambda: bridge.request_data_stream(0, 4),
        lambda: bridge.upload_mission(three_items()),
    ]


def test_without_allow_commands_nothing_but_heartbeats_goes_out():
    with link(allow_commands=False) as (bridge, vehicle):
        for call in every_new_call(bridge):
            with pytest.raises(RefusedError, match="allow_commands is False") as info:
                call()
            assert "\n" not in str(info.value)
        time.sleep(0.1)
        assert {m.get_type() for m in vehicle.received} == {"HEARTBEAT"}
        assert bridge.stats["commands_refused"] == 4


def test_an_unheard_vehicle_gets_nothing_but_a_one_line_error():
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
    try:
        with MavlinkBridge(f"udpin:127.0.0.1:{free_port(socket.SOCK_DGRAM)}", session, allow_commands=True) as bridge:
            for call, what in zip(
                every_new_call(bridge),
                ("command_long", "set_message_interval", "request_data_stream", "upload_mission"),
            ):
                with pytest.raises(LinkError, match=f"^{what}: no autopilot heard within the last 2.0 s$"):
                    call()
            assert bridge.stats["frames_out"] == bridge.stats["heartbeats_out"]
            assert bridge.autopilot is None and bridge.latest("HEARTBEAT") is None
    finally:
        session.close()


def test_bad_arguments_are_named_before_anything_is_checked_or_sent():
    bridge = MavlinkBridge("udpin:127.0.0.1:1", allow_commands=False)  # never started: nothing could go out
    for call, name in [
        (lambda: bridge.command_long(70000), "command"),
        (lambda: bridge.command_long(USER_1, [0] * 8), "params"),
        (lambda: bridge.command_long(USER_1, "1234"), "params"),
        (lambda: bridge.command_long(USER_1, (1, "x")), r"params\[1\]"),
        (lambda: bridge.command_long(USER_1, timeout=0), "timeout"),
        (lambda: bridge.command_long(USER_1, retries=-1), "retries"),
        (lambda: bridge.set_message_interval(-1, 1), "msg_id"),
        (lambda: bridge.set_message_interval(30, -1), "rate_hz"),
        (lambda: bridge.set_message_interval(30, math.inf), "rate_hz"),
        (lambda: bridge.set_message_interval(30, 1e-4), "rate_hz"),
        (lambda: bridge.request_data_stream(256, 1), "stream_id"),
        (lambda: bridge.request_data_stream(0, 1.5), "rate_hz"),
        (lambda: bridge.request_data_stream(0, 1, start=1), "start"),
        (lambda: bridge.upload_mission(three_items()[1:]), r"items\[0\]\.seq"),
        (lambda: bridge.upload_mission(three_items(), mission_type=7), "mission_type"),
        (lambda: bridge.upload_mission(three_items(), timeout=-1), "timeout"),
        (lambda: bridge.upload_mission(three_items(), retries=1.5), "retries"),
    ]:
        with pytest.raises(InputError, match=f"^{name}: ") as info:
            call()
        assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- the simulated front-seat
def test_bring_up_against_the_simulated_front_seat():
    """The front-seat takes a mission, accepts SET_MESSAGE_INTERVAL and REQUEST_DATA_STREAM as ArduSub
    does, and reports GUIDED and armed in its HEARTBEAT."""
    mission = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    port = free_port(socket.SOCK_DGRAM)
    fs = FrontSeat(mission, np.full(mission.dim, 0.5), f"udpin:127.0.0.1:{port}")
    thread = threading.Thread(target=fs.serve, name="frontseat", daemon=True)
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
    thread.start()
    try:
        with MavlinkBridge(f"udpout:127.0.0.1:{port}", session, allow_commands=True, heartbeat_hz=20.0) as bridge:
            wait_until(lambda: bridge.linked and bridge.autopilot, timeout=5, what="the front-seat's HEARTBEAT")
            assert (bridge.autopilot.type, bridge.autopilot.mode) == (M.MAV_TYPE_SUBMARINE, "MANUAL")
            position, _ = wait_until(lambda: bridge.latest("LOCAL_POSITION_NED"), what="a position")
            assert position.z >= 0

            result = bridge.set_message_interval(M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, 5)
            assert result == M.MAV_RESULT_ACCEPTED
            bridge.request_data_stream(M.MAV_DATA_STREAM_POSITION, 5)  # no reply exists; nothing breaks

            items = three_items()
            assert bridge.upload_mission(items) == M.MAV_MISSION_ACCEPTED
            assert [MissionItem.from_message(m) for m in fs.mission_items] == items

            assert bridge.set_mode("GUIDED") == M.MAV_RESULT_ACCEPTED
            assert bridge.arm(True) == M.MAV_RESULT_ACCEPTED
            wait_until(
                lambda: bridge.autopilot.armed and bridge.autopilot.mode == "GUIDED", timeout=3, what="armed, GUIDED"
            )
            assert bridge.arm(False) == M.MAV_RESULT_ACCEPTED
    finally:
        fs.stop()
        thread.join(timeout=5)
        fs.close()
        session.close()


def test_arm_and_set_mode_wait_for_the_ack():
    with rig(allow_commands=True) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        assert bridge.set_mode("guided") == mavlink2.MAV_RESULT_ACCEPTED
        assert vehicle.custom_mode == 4
        assert bridge.arm(True) == mavlink2.MAV_RESULT_ACCEPTED and vehicle.armed
        (cmd,) = [m for m in vehicle.messages("COMMAND_LONG") if m.command == mavlink2.MAV_CMD_DO_SET_MODE]
        assert (cmd.param1, cmd.param2) == (mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        with pytest.raises(ValueError, match="mode"):
            bridge.set_mode("WARP")
