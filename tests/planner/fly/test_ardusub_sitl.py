"""ArduSub's real firmware in the loop: the SITL launcher, and the bridge bringing the vehicle up as an operator would.

These tests need the ArduSub SITL binary named by ``ARDUSUB_SITL`` (CI sets it from
``../shared/ardusub/ardusub``) and skip with that reason where it is absent. The
bridge talks to the firmware over loopback TCP MAVLink and publishes on a real Zenoh
session; every process and thread is gone when a test ends.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from bridge import keys
from bridge.mavlink_bridge import MavlinkBridge
from bridge.mission_upload import MissionItem
from bridge.session import open_session
from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary
from rapt.errors import InputError, LinkTimeoutError, MissingFileError
from sim.uuv.missionfile import load_mission
from tests.support.loopback import free_port, wait_until

ROOT = Path(__file__).resolve().parents[3]
#: range2017's launch point (lat, lon, alt, heading), where a range team would put the vehicle.
LAUNCH = launch_point(load_mission(ROOT / "examples" / "range2017.toml"))
MAV_RESULT_ACCEPTED, MAV_RESULT_FAILED = 0, 4
MAV_MISSION_ACCEPTED = 0
ATTITUDE = 30  # message id
GUIDED, SURFACE, ALT_HOLD = 4, 9, 2  # ArduSub custom modes
SAFETY_ARMED = 128  # MAV_MODE_FLAG_SAFETY_ARMED

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")


def test_the_launcher_names_what_is_missing_in_one_line(tmp_path, monkeypatch):
    monkeypatch.delenv(ENV, raising=False)
    with pytest.raises(InputError, match=f"binary: set {ENV}"):
        ArduSubSitl(LAUNCH)
    with pytest.raises(MissingFileError, match="does not exist") as info:
        ArduSubSitl(LAUNCH, binary=tmp_path / "ardusub")
    assert "\n" not in str(info.value)
    (tmp_path / "sub.parm").write_text("FS_GCS_ENABLE 1\n")
    binary = tmp_path / "ardusub"
    binary.write_bytes(b"\x7fELF not for this machine")
    with pytest.raises(InputError, match="is not executable; chmod \\+x it"):
        ArduSubSitl(LAUNCH, binary=binary)
    binary.chmod(0o755)  # executable, but no program this machine runs
    before = set(Path(tempfile.gettempdir()).glob("ardusub-sitl-*"))
    with pytest.raises(InputError, match=r"cannot be run \(Exec format error\); build it for this machine") as info:
        ArduSubSitl(LAUNCH, binary=binary).start()
    binary.write_text("#!/bin/sh\necho 'starting'\necho 'Unknown option --bogus' >&2\nexit 3\n")
    with pytest.raises(LinkTimeoutError, match=r"exited with code 3 at start \(Unknown option --bogus\)") as info:
        ArduSubSitl(LAUNCH, binary=binary).start()
    assert "\n" not in str(info.value)
    assert set(Path(tempfile.gettempdir()).glob("ardusub-sitl-*")) == before  # nothing left behind


@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_the_bridge_gets_guided_only_once_the_estimator_is_ready_then_arms_and_disarms():
    """A cold boot at the launch point: GUIDED is retried until ArduSub accepts it, then armed in GUIDED."""
    with ArduSubSitl(LAUNCH, speedup=10) as sitl:
        session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
        heartbeats: list[dict] = []
        sub = session.declare_subscriber(
            keys.telemetry("uuv1", "HEARTBEAT"), lambda s: heartbeats.append(json.loads(s.payload.to_bytes()))
        )
        try:
            with MavlinkBridge(sitl.connection, session, vehicle="uuv1", allow_commands=True) as bridge:
                wait_until(lambda: bridge.target is not None, timeout=30, what="ArduSub's first HEARTBEAT")
                first = wait_until(lambda: heartbeats and heartbeats[0], timeout=10, what="HEARTBEAT on the bus")
                assert (first["type"], first["autopilot"]) == (12, 3)  # MAV_TYPE_SUBMARINE, ARDUPILOTMEGA
                assert not first["base_mode"] & SAFETY_ARMED

                answers = []
                deadline = time.monotonic() + 120  # the EKF needs about 40 s of vehicle time
                while time.monotonic() < deadline:
                    answers.append(bridge.set_mode("GUIDED"))
                    if answers[-1] == MAV_RESULT_ACCEPTED:
                        break
                    time.sleep(0.5)
                assert answers[-1] == MAV_RESULT_ACCEPTED, answers
                assert set(answers[:-1]) <= {MAV_RESULT_FAILED}  # "GUIDED requires position" until then

                assert bridge.arm(True) == MAV_RESULT_ACCEPTED
                wait_until(
                    lambda: heartbeats[-1]["custom_mode"] == GUIDED and heartbeats[-1]["base_mode"] & SAFETY_ARMED,
                    timeout=10,
                    what="an armed GUIDED heartbeat",
                )
                assert bridge.arm(False) == MAV_RESULT_ACCEPTED
                wait_until(lambda: not heartbeats[-1]["base_mode"] & SAFETY_ARMED, timeout=10, what="disarmed")
        finally:
            sub.undeclare()
            session.close()
        process = sitl.process
    assert process is not None and process.poll() is not None  # stopped by its id at exit


@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_the_bridge_sets_a_message_rate_and_uploads_a_mission_that_reads_back():
    """SET_MESSAGE_INTERVAL is ACCEPTED and changes ATTITUDE's rate (in vehicle time); a home and two
    waypoints at depth upload with MAV_MISSION_ACCEPTED; read back on SERIAL1, the waypoints are as sent
    and item 0 holds the vehicle's own home, not the uploaded one."""
    lat, lon = LAUNCH[:2]
    items = [
        MissionItem.waypoint(0, lat + 1e-3, lon + 1e-3, 0.0),  # a home ArduSub will not keep
        MissionItem.waypoint(1, lat + 2e-4, lon, -2.0),
        MissionItem.waypoint(2, lat + 2e-4, lon + 3e-4, -3.0),
    ]
    with ArduSubSitl(LAUNCH, speedup=10) as sitl:
        session = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
        stamps: list[int] = []  # ATTITUDE.time_boot_ms: rates in vehicle time, whatever the speed-up
        sub = session.declare_subscriber(
            keys.telemetry("uuv1", "ATTITUDE"),
            lambda s: stamps.append(json.loads(s.payload.to_bytes())["time_boot_ms"]),
        )

        def rate_hz(wall_s: float = 1.0) -> float:
            start = len(stamps)
            time.sleep(wall_s)
            got = stamps[start:]
            return (len(got) - 1) / ((got[-1] - got[0]) / 1000)

        try:
            with MavlinkBridge(sitl.connection, session, vehicle="uuv1", allow_commands=True) as bridge:
                wait_until(lambda: bridge.autopilot is not None, timeout=30, what="ArduSub's first HEARTBEAT")
                assert (bridge.autopilot.type, bridge.autopilot.autopilot, bridge.autopilot.mode) == (12, 3, "MANUAL")
                wait_until(lambda: len(stamps) > 20, timeout=10, what="ATTITUDE")
                before = rate_hz()
                assert bridge.set_message_interval(ATTITUDE, 25.0) == MAV_RESULT_ACCEPTED
                time.sleep(0.2)
                after = rate_hz()
                assert before < 15 and 20 < after < 30, (before, after)
                assert bridge.latest("COMMAND_ACK")[0].command == 511

                assert bridge.upload_mission(items) == MAV_MISSION_ACCEPTED

                gcs = mavutil.mavlink_connection(
                    f"tcp:127.0.0.1:{sitl.port + 2}", source_system=1, source_component=190, dialect="ardupilotmega"
                )
                try:
                    assert gcs.wait_heartbeat(timeout=10) is not None
                    stored = download_mission(gcs)
                finally:
                    gcs.close()
        finally:
            sub.undeclare()
            session.close()
    assert len(stored) == 3
    # the frame comes back as GLOBAL_RELATIVE_ALT (3): ArduPilot stores no _INT variant, and x/y are degE7 anyway
    assert [(m.seq, m.frame, m.command, m.x, m.y, m.z) for m in stored[1:]] == [
        (i.seq, 3, i.command, i.x, i.y, i.z) for i in items[1:]
    ]
    home = stored[0]  # ArduPilot's seq 0 is home: its own, in the absolute frame
    assert home.frame == 0 and abs(home.x - round(lat * 1e7)) < 100 and abs(home.y - round(lon * 1e7)) < 100


def download_mission(gcs, timeout: float = 5.0) -> list:
    """MISSION_REQUEST_LIST -> MISSION_COUNT -> MISSION_REQUEST_INT for each item, over a separate link."""
    gcs.mav.mission_request_list_send(1, 1, 0)
    count = gcs.recv_match(type="MISSION_COUNT", blocking=True, timeout=timeout)
    assert count is not None, "no MISSION_COUNT"
    stored = []
    for seq in range(count.count):
        gcs.mav.mission_request_int_send(1, 1, seq, 0)
        item = gcs.recv_match(type="MISSION_ITEM_INT", blocking=True, timeout=timeout)
        assert item is not None and item.seq == seq, f"item {seq}"
        stored.append(item)
    gcs.mav.mission_ack_send(1, 1, 0, 0)
    return stored


@contextlib.contextmanager
def _watched(port: int):
    """The crew's Foxglove (a Python client of the live view on ``port``), connecting while the firmware is
    brought up and flown: ``{"client": ...}`` once connected."""
    from tests.support.foxglove_client import FoxgloveClient

    watched: dict = {}

    def watch() -> None:
        deadline = time.monotonic() + 60
        while "client" not in watched and time.monotonic() < deadline:
            try:
                watched["client"] = FoxgloveClient(f"ws://127.0.0.1:{port}")
            except Exception:  # not serving yet
                time.sleep(0.05)

    watcher = threading.Thread(target=watch, name="foxglove-watch")
    watcher.start()
    try:
        yield watched
    finally:
        watcher.join(timeout=70)


def _saw_the_log_live(client, fixes: list[dict], channels: dict) -> None:
    """What the crew saw live: the log's fixes (thinned to a screen's rate), the map, the bring-up's events."""
    by_stamp: dict = {}  # a stamp is the bridge's receive time: reports read in one go share it
    for f in fixes:
        by_stamp.setdefault((f["timestamp"]["sec"], f["timestamp"]["nsec"]), []).append(f)
    seen = client.received("/vehicle/fix")
    assert len(seen) > 10 and all(f in by_stamp[(f["timestamp"]["sec"], f["timestamp"]["nsec"])] for f in seen)
    [doc] = client.received("/map/scenario")[-1:]
    assert json.loads(doc["geojson"]) == json.loads(channels["/map/scenario"].messages[0]["geojson"])
    events = [m["message"] for m in client.received("/vehicle/log")]
    assert any(e.startswith("bring-up heartbeat ok") for e in events), events
    assert "/status/bridge" in client.topics and "/status/logger" in client.topics, sorted(client.topics)
    latency = [m["decisions"]["latency_ms_p99"] for m in client.received("/status/autonomy") if "decisions" in m]
    assert latency and latency[-1] is not None  # the back-seat's decision latency, to plot


@pytest.mark.slow  # the firmware's whole range loop with a live client, about 40 s; CI runs it with the slow ones
@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_a_plan_scenario_flown_on_ardusub_like_on_the_range(tmp_path):
    """`rapt-plan run PLAN --scenario pair2b --mavlink` on the real firmware: bring-up, a vehicle-paced flight
    towards the first waypoint, the vehicle surfaced and disarmed at the end, a log read back as a run."""
    from pathlib import Path

    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.run import run_vehicle
    from planner.review.logs import read_run

    flight = flight_from_plan(Path("field_plans/range2017/plan.json"), "pair2b")
    log = tmp_path / "pair2b.mcap"
    port = free_port()
    with ArduSubSitl(LAUNCH, speedup=10) as sitl, _watched(port) as watched:
        result = run_vehicle(flight, sitl.connection, log_path=log, timeout_s=20.0, live=("127.0.0.1", port))
    client = watched["client"]
    client.close()
    steps = [(s.name, s.status) for s in result.timeline]
    names = ["heartbeat", "streams", "estimate", "area", "start", "guard", "mission", "guided", "arm", "depth", "clock"]
    assert steps[: len(names)] == [(n, "ok") for n in names], steps
    assert steps[-1] == ("recover", "ok") and "disarmed" in result.timeline[-1].detail
    assert result.ended.startswith("wall-time limit") and not result.watchdog
    d = result.decisions
    assert d["missed"] == 0 and d["decisions"] >= 0.8 * result.sim_s / flight.mission.dt
    assert d["latency_ms_p99"] < 50
    # it flew towards the first waypoint (ArduSub's BlueROV2 is slower than the modelled vehicle)
    wx, wy = flight.mission.waypoints[0]
    track = result.track
    start = ((track[0, 1] - wx) ** 2 + (track[0, 2] - wy) ** 2) ** 0.5
    end = ((track[-1, 1] - wx) ** 2 + (track[-1, 2] - wy) ** 2) ** 0.5
    assert start - end > 50, (start, end)
    run = read_run(log)
    assert run.scenario_id == "pair2b" and run.has_end and len(run.steps) == len(track)
    assert [e["name"] for e in run.events if e["source"] == "bringup"][: len(names)] == names
    # Foxglove: the firmware's own position and STATUSTEXT under Foxglove's schemas, the map beneath them
    from bridge.logger import read_log
    from tests.support.foxglove_check import check_channel, foxglove_channels

    channels = foxglove_channels(log)
    for channel in channels.values():
        check_channel(channel)
    gpi = [m for t, _, m in read_log(log) if t == "rapt/uuv1/mavlink/GLOBAL_POSITION_INT"]
    fixes = channels["/vehicle/fix"].messages
    assert len(fixes) == len(gpi) > 10
    assert (fixes[-1]["latitude"], fixes[-1]["longitude"]) == (gpi[-1]["lat"] / 1e7, gpi[-1]["lon"] / 1e7)
    texts = [m for t, _, m in read_log(log) if t == "rapt/uuv1/mavlink/STATUSTEXT"]
    vehicle_lines = [m for m in channels["/vehicle/log"].messages if m["name"] == "vehicle"]
    assert texts and len(vehicle_lines) == len(texts)
    assert len(channels["/map/scenario"].messages) == 1
    _saw_the_log_live(client, fixes, channels)
    # and the run was sound: no automatic check failed on the firmware's own flight
    checks = {c["name"]: c for c in run.checks}
    assert not [c for c in checks.values() if c["verdict"] == "fail"], checks
    assert checks["estimator"]["verdict"] == "pass" and checks["thrusters"]["verdict"] in ("pass", "warn")
    # the range day's next step: `rapt-plan compare` reads the firmware's log like any other run's
    from planner.review.compare import compare
    from planner.review.runs import CompareConfig

    out = tmp_path / "comparison"
    comparison = compare("field_plans/range2017/plan.json", [log], out, CompareConfig(dithers=0, bootstrap=0))
    [row] = comparison["scenarios"]
    assert row["id"] == "pair2b" and row["log"] == log.name and (out / "comparison.json").is_file()
    assert row["log_complete"] and row["ended"] == result.ended and row["steps"] == len(track)
    assert row["path_error_m"] is not None and row["predicted_mode"] in ("TF", "SS", "MS", "TS")


@pytest.mark.slow  # a firmware boot and flight of about 10 s
@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_ardusubs_ground_station_failsafe_ends_the_run_and_the_vehicle_is_left_alone(tmp_path):
    """A ground station (system 255) beats through the bring-up and falls silent mid-run: ArduSub's own
    failsafe (FS_GCS_ENABLE 2) disarms it, the run ends at once with that reason, nothing more is
    commanded, and the log is closed and readable."""
    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.run import run_vehicle
    from planner.review.logs import read_run

    flight = flight_from_plan(Path("field_plans/range2017/plan.json"), "pair2b")
    log = tmp_path / "failsafe.mcap"
    texts: list[str] = []
    with ArduSubSitl(LAUNCH, speedup=10) as sitl:
        gcs = mavutil.mavlink_connection(f"tcp:127.0.0.1:{sitl.port + 2}", source_system=255, source_component=190)
        beating, stop = threading.Event(), threading.Event()
        beating.set()

        def ground_station() -> None:  # 20 Hz of wall time: 2 Hz of vehicle time at speed-up 10
            while not stop.is_set():
                if beating.is_set():
                    gcs.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
                while (msg := gcs.recv_msg()) is not None:  # keep the firmware's stream to it drained
                    if msg.get_type() == "STATUSTEXT":
                        texts.append(msg.text)
                time.sleep(0.05)

        def say(step) -> None:
            if step.name == "clock":  # flying: the ground station goes quiet 2 s (20 vehicle s) later
                threading.Timer(2.0, beating.clear).start()

        station = threading.Thread(target=ground_station, name="gcs", daemon=True)
        station.start()
        try:
            result = run_vehicle(flight, sitl.connection, log_path=log, timeout_s=30.0, say=say)
        finally:
            stop.set()
            station.join(timeout=5)
            gcs.close()
    assert result.ended == "vehicle: disarmed itself (a failsafe, or disarmed by someone else)", result.ended
    assert not result.watchdog and result.timeline[-1].detail == f"nothing commanded: {result.ended}"
    assert any("heartbeat lost" in t for t in texts), texts  # ArduSub's own words: it was its failsafe
    run = read_run(log)
    assert run.has_end and run.scenario_id == "pair2b"
    # the automatic run checks see it: ArduSub's failsafe message, and a disarm nobody commanded
    checks = {c["name"]: c for c in run.checks}
    assert checks["statustext"]["verdict"] == "fail" and "heartbeat lost" in checks["statustext"]["reason"]
    assert checks["modes"]["verdict"] == "fail" and "disarmed" in checks["modes"]["reason"]


@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_a_vehicle_port_another_client_holds_is_one_line_and_nothing_is_commanded(tmp_path):
    """SERIAL0 serves one client: with a ground station already on it, the run gets no HEARTBEAT and
    stops at the first bring-up step in one line, its log closed and readable."""
    import socket

    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.bringup import BringUpTimeouts
    from planner.fly.vehicle.run import run_vehicle
    from planner.review.logs import read_run
    from rapt.errors import LinkTimeoutError

    flight = flight_from_plan(Path("field_plans/range2017/plan.json"), "pair2b")
    log = tmp_path / "busy.mcap"
    with ArduSubSitl(LAUNCH, speedup=10) as sitl:
        with socket.create_connection(("127.0.0.1", sitl.port), timeout=5) as other:
            other.recv(1)  # the firmware serves it: the port is taken
            with pytest.raises(LinkTimeoutError) as info:
                run_vehicle(flight, sitl.connection, log_path=log, timeouts=BringUpTimeouts(heartbeat=3.0))
    line = str(info.value)
    assert line == (
        f"--mavlink {sitl.connection}: no HEARTBEAT from an autopilot within 3 s; check the address and that "
        "the vehicle is on and that no other program holds the port"
    )
    run = read_run(log)
    assert [e["name"] for e in run.events if e["source"] == "bringup"] == ["heartbeat"]


@pytest.mark.slow  # a firmware boot and flight of about 10 s
@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_a_firmware_that_never_gets_a_position_estimate_is_never_armed(tmp_path):
    """With no horizontal position source for its EKF (EK3_SRC1_POSXY 0: a sensor setting, no failsafe
    touched), ArduSub never reports an absolute position: the bring-up stops at its estimate step in
    one line after 80 s of vehicle time, GUIDED never asked, nothing armed, the log readable."""
    from planner.fly.flight import flight_from_plan
    from planner.fly.vehicle.bringup import BringUpTimeouts
    from planner.fly.vehicle.run import run_vehicle
    from planner.review.logs import read_run
    from rapt.errors import LinkTimeoutError

    flight = flight_from_plan(Path("field_plans/range2017/plan.json"), "pair2b")
    log = tmp_path / "no-estimate.mcap"
    with ArduSubSitl(LAUNCH, speedup=10, parameters={"EK3_SRC1_POSXY": 0}) as sitl:
        with pytest.raises(LinkTimeoutError) as info:
            run_vehicle(flight, sitl.connection, log_path=log, timeouts=BringUpTimeouts(estimate=8.0))
    assert str(info.value).startswith("bring-up estimate: no position estimate within 8 s"), str(info.value)
    assert "\n" not in str(info.value)
    steps = [(e["name"], e["status"]) for e in read_run(log).events if e["source"] == "bringup"]
    assert steps == [("heartbeat", "ok"), ("streams", "ok"), ("estimate", "failed")], steps
    with pytest.raises(InputError, match="parameters: EK3 SRC=1 is not an ArduPilot parameter"):
        ArduSubSitl(LAUNCH, parameters={"EK3 SRC": 1})


def test_the_launch_point_is_where_the_modelled_vehicle_starts():
    """SITL's home is the mission's launch in its local frame, heading for the first waypoint, as the model starts."""
    import math

    from sim.uuv.geo import LocalFrame
    from sim.uuv.scenario import make_scenarios
    from sim.uuv.world import World

    for name in ("range2017", "imitation7"):
        mission = load_mission(ROOT / "examples" / f"{name}.toml")
        lat, lon, alt, heading = launch_point(mission)
        state = World(make_scenarios(mission, np.full((1, mission.dim), 0.5))).state
        east, north = LocalFrame(mission.origin_lat, mission.origin_lon).to_local(lat, lon)
        assert math.hypot(east - state.x[0], north - state.y[0]) < 0.01, name
        assert alt == 0.0 and abs(heading - math.degrees(state.heading[0]) % 360) < 1e-6, name
    # the home range2017's field plan wrote into its WPL files, to the file's 8 decimals
    home = (ROOT / "field_plans" / "range2017" / "pair1a.waypoints").read_text().splitlines()[1].split("\t")
    assert (round(LAUNCH[0], 8), round(LAUNCH[1], 8)) == (float(home[8]), float(home[9]))


#: imitation7's scenario whose straight route runs into obstacle O2 about 150 m out (the bare-autopilot test's own).
OBSTACLE_SCENARIO = 231
#: Fast enough for the default run; the decisions keep up with the firmware (none missed) on 2 loaded cores.
FLIGHT_SPEEDUP = 20.0


def _imitation7_flight(sonar_range_m: float | None = None):
    """imitation7's obstacle scenario; ``sonar_range_m`` shortens the (virtual) sonar's reach in the mission file."""
    from planner.fly.flight import Flight
    from sim.uuv.missionfile import load_mission_text

    path = ROOT / "examples" / "imitation7.toml"
    text = path.read_text()
    if sonar_range_m is not None:
        text = text.replace("[vehicle]\n", f"[vehicle]\nsonar_range_m = {sonar_range_m}\n", 1)
    mission = load_mission_text(text, str(path))
    u = np.random.default_rng(1).random((400, mission.dim))[OBSTACLE_SCENARIO]
    return Flight(mission, u, f"imitation7-{OBSTACLE_SCENARIO}", str(path))


@pytest.mark.slow  # a firmware flight past an obstacle; CI runs it with the slow ones
@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
def test_a_virtual_obstacle_in_the_way_is_seen_and_gone_round_on_ardusub():
    """The bare-autopilot test's obstacle scenario on the firmware, from the mission's own launch point:
    the virtual sonar reports the obstacle the vehicle has no sonar for, the back-seat goes round it and
    on past it, no watchdog rule broken and no decision missed.  ArduSub's BlueROV2 makes about 1.5 m/s
    of the 2 m/s asked, is closest to O2 about 80 s in and passes it 41 m off (the batch model: 18 m)."""
    from planner.fly.vehicle.run import run_vehicle
    from sim.uuv.geometry import polygon_signed_distance
    from sim.uuv.scenario import make_scenarios

    flight = _imitation7_flight()
    mission = flight.mission
    o2 = [o.name for o in mission.obstacles].index("O2")
    obstacles = make_scenarios(mission, flight.u[None, :]).obstacles
    (lx, ly), (wx, wy) = mission.launch, mission.waypoints[0]
    s = np.linspace(0, 1, 751)
    straight = polygon_signed_distance(lx + s * (wx - lx), ly + s * (wy - ly), np.repeat(obstacles, len(s), axis=0))
    assert straight[0][:, o2].min() < 0  # the straight route runs through O2: it is in the way
    # 200 s of flight takes it round and past O2, before the firmware's simulated pack (BATT_CAPACITY
    # 3300 mAh) reaches the watchdog's 10 % about 290 s after boot
    with ArduSubSitl(launch_point(mission), speedup=FLIGHT_SPEEDUP) as sitl:
        result = run_vehicle(flight, sitl.connection, timeout_s=200 / FLIGHT_SPEEDUP)
    assert result.ended.startswith("wall-time limit") and not result.watchdog and not result.violations, result.ended
    assert result.decisions["missed"] == 0 and result.sim_s > 150
    x, y = result.track[:, 1], result.track[:, 2]
    d = polygon_signed_distance(x, y, np.repeat(obstacles, len(x), axis=0))[0]
    assert d.min() > 0  # never touched one
    assert d[:, o2].min() < 50  # went round O2 close by, not far away from it
    assert y[-1] > obstacles[0, o2, :, 1].max()  # and on past it, north of its northmost corner
    # the firmware has no sonar: what the back-seat went round came from the virtual one
    assert result.virtual["contacts_sent"] > 0 and result.virtual["gauge_sent"] > 0


@needs_firmware  # the default run's firmware flight (about 10 s)
@pytest.mark.sitl
@pytest.mark.integration
def test_the_watchdog_surfaces_ardusub_when_the_vehicle_touches_a_virtual_obstacle(tmp_path):
    """The same scenario with a sonar that reaches 1 m (a mission-file setting): the back-seat sees O2 too
    late and touches it; the watchdog takes over at once with SURFACE, ArduSub rises to the surface (and
    there, as its SURFACE mode does, switches itself to ALT_HOLD), the run ends with the collision and
    the vehicle is disarmed; after the take-over only SURFACE and the disarm are commanded, the log is
    closed and reads back with the watchdog's event."""
    from bridge.logger import read_log
    from planner.fly.vehicle.run import run_vehicle
    from planner.review.logs import read_run

    flight = _imitation7_flight(sonar_range_m=1.0)
    log = tmp_path / "collision.mcap"
    with ArduSubSitl(launch_point(flight.mission), speedup=FLIGHT_SPEEDUP) as sitl:
        result = run_vehicle(flight, sitl.connection, log_path=log, timeout_s=200 / FLIGHT_SPEEDUP)
    assert result.watchdog == "collision", result.ended
    assert result.ended in ("collision", "watchdog: collision")  # the referee's word or the watchdog's
    assert result.decisions["missed"] == 0
    assert result.timeline[-1].name == "recover" and result.timeline[-1].detail == "surfaced and disarmed"

    run = read_run(log)
    assert run.has_end and run.ended == result.ended and not run.problems
    [event] = [e for e in run.events if e["source"] == "watchdog"]
    assert (event["event"], event["reason"], event["action"]) == ("intervention", "collision", "surface")
    assert event["mode_result"] == MAV_RESULT_ACCEPTED and event["detail"].startswith("touched obstacle O2")
    records = list(read_log(log))
    taken = next(ns for t, ns, m in records if t.endswith("/control/active") and m["value"] == "watchdog")
    after = [(t, m) for t, ns, m in records if ns >= taken]
    acks = [m["command"] for t, m in after if t.endswith("/mavlink/COMMAND_ACK")]
    assert acks and set(acks) <= {176, 400}, acks  # DO_SET_MODE (SURFACE) and the disarm, nothing else
    assert all(m["result"] == MAV_RESULT_ACCEPTED for t, m in after if t.endswith("/mavlink/COMMAND_ACK"))
    modes = [
        (m["custom_mode"], bool(m["base_mode"] & SAFETY_ARMED)) for t, m in after if t.endswith("/mavlink/HEARTBEAT")
    ]
    first = next(i for i, (mode, _) in enumerate(modes) if mode == SURFACE)
    assert set(modes[:first]) <= {(GUIDED, True)}, modes  # a beat sent before the take-over reached it
    assert {mode for mode, _ in modes[first:]} <= {SURFACE, ALT_HOLD}, modes  # never GUIDED again
    assert modes[-1] in ((SURFACE, False), (ALT_HOLD, False)), modes  # disarmed, at the surface
    assert not any(t.endswith("/control/active") and m["value"] != "watchdog" for t, m in after)
    depth = [-m["relative_alt"] / 1000 for t, m in after if t.endswith("/mavlink/GLOBAL_POSITION_INT")]
    assert depth[-1] < 0.5 < max(depth), depth[-1]  # it was under and came up
