"""The vehicle-paced back-seat: decisions by the vehicle's clock, the same at any replay speed, none on stale telemetry."""

from __future__ import annotations

import json
import math
import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.session import open_session  # noqa: E402
from planner.common.plans import load_plan  # noqa: E402
from planner.common.telemetry import VIRTUAL_BATTERY_ID, VehicleTelemetry  # noqa: E402
from planner.fly.backseat import BackSeat, DecisionClock  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402

PLAN = "field_plans/range2017/plan.json"
START_MS = 10_000


@pytest.fixture(scope="module")
def plan():
    return load_plan(PLAN)


@pytest.fixture
def session():
    s = open_session(listen=[f"tcp/127.0.0.1:{free_port()}"])
    yield s
    s.close()


def _stream(mission, *, seconds: float = 40.0, attitude_until_s: float | None = None) -> list[bytes]:
    """A vehicle's reports: cruising north from launch at 1.5 m/s and 2 m depth, at its own rates.

    GLOBAL_POSITION_INT and ATTITUDE at 10 Hz, the fuel gauge at 2 Hz; one report arrives
    twice and one arrives late (after a newer one), as on a real network.
    """
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    x0, y0 = mission.launch
    frames: list[bytes] = []
    late = None
    for k in range(int(seconds * 10)):
        ms = START_MS + 100 * k
        t = k / 10
        lat, lon = frame.to_latlon(x0, y0 + 1.5 * t)
        gpi = mavlink.MAVLink_global_position_int_message(
            ms, int(round(lat * 1e7)), int(round(lon * 1e7)), -2000, -2000, 150, 0, 0, 0
        )
        frames.append(gpi.pack(mav))
        if k == 50:
            frames.append(gpi.pack(mav))  # a repeated report
        if attitude_until_s is None or t < attitude_until_s:
            att = mavlink.MAVLink_attitude_message(ms + 50, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
            if k == 120:
                late = att.pack(mav)  # held back: delivered after the next one
            else:
                frames.append(att.pack(mav))
                if late is not None and k == 121:
                    frames.append(late)
        if k % 5 == 0:
            bat = mavlink.MAVLink_battery_status_message(
                VIRTUAL_BATTERY_ID, 0, 0, 32767, [16000] + [65535] * 9, 1000, -1, 10 * k, 80
            )
            frames.append(bat.pack(mav))
    return frames


def _fly(session, mission, u, frames: list[bytes], pause_s: float, **kw) -> tuple[list[dict], BackSeat]:
    v = "uuv1"
    commands = session.declare_subscriber(keys.command(v, "autonomy"))
    pub = session.declare_publisher(keys.raw(v))
    seat = BackSeat(session, v, mission, u, pacing="vehicle", **kw)
    seat.begin(START_MS)
    seat.start()
    try:
        for f in frames:
            pub.put(f)
            if pause_s:
                time.sleep(pause_s)
        wait_until(lambda: seat.telemetry.counts.messages >= len(frames), 20, "the stream")
        time.sleep(0.1)
    finally:
        seat.close()
    out = []
    while (sample := commands.try_recv()) is not None:
        out.append(json.loads(sample.payload.to_bytes()))
    commands.undeclare()
    pub.undeclare()
    return out, seat


def test_decision_clock_counts_missed_periods():
    clock = DecisionClock(1000, 2000)
    assert not clock.due(900)
    assert clock.due(1000) and not clock.due(2900)
    assert clock.due(3050)
    assert clock.due(9100)  # 5000 and 7000 passed with no report
    assert clock.missed == 2 and clock.next_ms == 11000


def test_same_decisions_at_two_replay_speeds(session, plan):
    mission, u = plan.mission, plan.u("pair2b")
    frames = _stream(mission)
    fast, seat_fast = _fly(session, mission, u, frames, 0.0)
    slow, seat_slow = _fly(session, mission, u, frames, 0.0015)
    decisions = list({c["tick_ms"]: c for c in fast}.values())  # a refresh repeats its decision
    # one per 2 s of the vehicle's clock over 40 s, but the first: no fuel reading had come yet
    assert [c["tick_ms"] for c in decisions] == list(range(START_MS + 2000, START_MS + 40_000, 2000))
    assert len(fast) > len(decisions)  # refreshed within each period
    assert fast == slow  # the same set-points, refreshes included, whatever the wall-clock pace
    assert seat_fast.stats.decisions == seat_slow.stats.decisions == 19
    assert seat_fast.stats.missed == 0 and seat_fast.stats.stale == 1
    counts = seat_fast.telemetry.counts
    assert counts.duplicates >= 1 and counts.out_of_order == 1
    # it holds the mission depth (2 m) rather than diving on: a real autopilot integrates vz
    assert all(abs(c["vz"]) < 0.05 for c in decisions)
    # it heads for the first waypoint from launch
    x0, y0 = mission.launch
    wx, wy = mission.waypoints[0]
    bearing = math.atan2(wx - x0, wy - y0)
    assert abs(math.remainder(decisions[0]["yaw"] - bearing, 2 * math.pi)) < 0.5


def test_stale_telemetry_stops_commands(session, plan):
    mission, u = plan.mission, plan.u("pair2b")
    frames = _stream(mission, attitude_until_s=10.0)  # the heading stops coming after 10 s
    out, seat = _fly(session, mission, u, frames, 0.0)
    last_attitude_ms = START_MS + 9_900 + 50
    assert seat.stats.stale > 0
    assert out, "it commanded while the telemetry was fresh"
    # nothing commanded on a heading older than the limit (2 periods = 4 s), refreshes included
    assert max(c["tick_ms"] for c in out) <= last_attitude_ms + seat.stale_ms
    assert seat.stats.decisions == 6  # 12, 14, ... 22 s: the heading is at most 4 s old


def test_telemetry_reads_a_real_vehicles_frames(plan):
    mission = plan.mission
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    tel = VehicleTelemetry(frame, VIRTUAL_BATTERY_ID)
    lat, lon = frame.to_latlon(-480.0, -520.0)
    tel.add(mavlink.MAVLink_global_position_int_message(500, 0, 0, 0, 0, 0, 0, 0, 65535))
    assert tel.pose is None  # ArduSub reports 0, 0 before it has an origin
    tel.add(mavlink.MAVLink_attitude_message(990, 0, 0, math.pi / 2, 0, 0, 0.1))
    tel.add(
        mavlink.MAVLink_global_position_int_message(1000, round(lat * 1e7), round(lon * 1e7), 0, -1500, 100, 0, 0, 0)
    )
    pose = tel.pose
    assert pose is not None and abs(pose.east + 480) < 0.02 and abs(pose.north + 520) < 0.02
    assert pose.depth == 1.5 and pose.heading == pytest.approx(math.pi / 2) and pose.speed == 1.0
    # a contact 10 m ahead and 2 m to the right of a vehicle heading east is 10 m east, 2 m south
    tel.add(mavlink.MAVLink_obstacle_distance_3d_message(1000, 1, mavlink.MAV_FRAME_BODY_FRD, 3, 10.0, 2.0, 0, 0.1, 50))
    tel.add(mavlink.MAVLink_obstacle_distance_3d_message(1000, 1, mavlink.MAV_FRAME_BODY_FRD, 4, 5.0, 0.0, 0, 0.1, 50))
    c = tel.contacts[3]
    assert c.east == pytest.approx(-470, abs=0.05) and c.north == pytest.approx(-522, abs=0.05)
    assert 4 in tel.contacts  # same time, another contact: not a duplicate
    # the pack's reading is kept, but the run counts on the gauge; energy from mAh x V when not reported
    tel.add(mavlink.MAVLink_battery_status_message(0, 0, 0, 0, [16000] + [65535] * 9, 0, 500, -1, 90))
    assert tel.pack is not None and tel.energy_hj is None
    tel.add(mavlink.MAVLink_battery_status_message(VIRTUAL_BATTERY_ID, 0, 0, 0, [16000] + [65535] * 9, 0, 500, -1, 90))
    assert tel.energy_hj == int(500 * 16000 / 1e6 * 36)
    # late and repeated reports are dropped and counted
    assert tel.add(mavlink.MAVLink_global_position_int_message(900, 1, 1, 0, 0, 0, 0, 0, 0)) is None
    assert tel.counts.out_of_order == 1
    # a rebooted vehicle's clock starts again
    tel.add(mavlink.MAVLink_global_position_int_message(200_000, round(lat * 1e7), round(lon * 1e7), 0, 0, 0, 0, 0, 0))
    assert tel.add(
        mavlink.MAVLink_global_position_int_message(50, round(lat * 1e7), round(lon * 1e7), 0, 0, 0, 0, 0, 0)
    )
    assert tel.counts.reboots == 1 and tel.pose.time_ms == 50


def _depth_profile(tel: VehicleTelemetry, frame: LocalFrame, depths: list[float], period_ms: int = 200) -> list[bool]:
    """Feed one position report per ``period_ms`` at each depth; whether each pose counted as surfaced."""
    lat, lon = frame.to_latlon(-480.0, -520.0)
    out = []
    for k, depth in enumerate(depths):
        msg = mavlink.MAVLink_global_position_int_message(
            1000 + k * period_ms, round(lat * 1e7), round(lon * 1e7), 0, round(-depth * 1000), 0, 0, 0, 0
        )
        tel.add(msg)
        out.append(tel.pose.surfaced)
    return out


def test_a_vehicle_floating_with_its_sensor_below_the_waterline_counts_as_surfaced(plan):
    # ArduSub SITL under a surface command floats at 0.36 m: a depth rule of "near 0" never says
    # surfaced, and a transmission that waits for it never goes out
    mission = plan.mission
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    tel = VehicleTelemetry(frame, VIRTUAL_BATTERY_ID)
    rising = [2.0 - 0.1 * k for k in range(17)]  # 2.0 -> 0.4 m at 0.5 m/s
    floating = [0.36 + 0.01 * (k % 2) for k in range(30)]  # 6 s at the top, bobbing 1 cm
    flags = _depth_profile(tel, frame, [2.0] * 20 + rising + floating)
    assert not any(flags[: 20 + 17]), "at depth or rising is never surfaced"
    top = flags[20 + 17 :]
    assert not any(top[:14]), "not before the depth has stopped rising for 3 s"
    assert all(top[16:]), "floating at 0.36 m for more than 3 s is surfaced"
    # diving again ends it at once; a vehicle holding its running depth never counts
    assert _depth_profile(tel, frame, [0.5, 0.8, 1.1]) == [False, False, False]
    still = VehicleTelemetry(frame, VIRTUAL_BATTERY_ID)
    assert not any(_depth_profile(still, frame, [1.2] * 40))
    # a real reading of 0 is surfaced at once, as before
    assert _depth_profile(VehicleTelemetry(frame, VIRTUAL_BATTERY_ID), frame, [0.1]) == [True]


def test_a_contacts_fed_surrogate_decides_by_the_vehicles_clock_and_a_scan_fed_one_is_refused(session):
    """A surrogate that sees what the expert sees (contacts over OBSTACLE_DISTANCE_3D, no scan) flies a
    vehicle-paced back-seat: one decision per 2 s of the vehicle's clock, heading for the waypoint until
    the vehicle's fuel gauge falls below its 15 %, then for the recovery point.  A scan-fed surrogate
    needs the simulator's 360-degree scan, which a vehicle does not send."""
    from rapt.errors import InputError
    from sim.uuv.imitation.surrogate import Surrogate
    from tests.support.hand_policy import IMITATION7, GreedyPolicy

    u = [0.5] * IMITATION7.dim
    sur = Surrogate.for_mission(IMITATION7, GreedyPolicy())
    got, seat = _fly(session, IMITATION7, u, _stream(IMITATION7), 0.0, surrogate=sur, source="autonomy")
    decisions = list({c["tick_ms"]: c for c in got}.values())
    assert [c["tick_ms"] for c in decisions] == list(range(START_MS + 2000, START_MS + 40_000, 2000))
    x0, y0 = IMITATION7.launch
    rx, ry = IMITATION7.recovery

    def towards(c, gx, gy):  # the stream cruises north from launch at 1.5 m/s, heading north
        y = y0 + 1.5 * (c["tick_ms"] - START_MS) / 1000
        return abs(math.remainder(c["yaw"] - math.atan2(gx - x0, gy - y), 2 * math.pi)) < 0.05

    wx, wy = IMITATION7.waypoints[0]
    assert all(towards(c, wx, wy) for c in decisions[:4])  # 22.5 % charge at launch; the stream drains it fast
    assert all(towards(c, rx, ry) for c in decisions[5:])  # below 15 % after about 10 s: home, and latched
    scan = Surrogate.for_mission(IMITATION7, GreedyPolicy(spec=_scan_spec()), observation="scan")
    with pytest.raises(InputError, match="a scan-fed surrogate needs the simulator's sonar scan; fly it lock-step"):
        BackSeat(session, "uuv2", IMITATION7, u, surrogate=scan, pacing="vehicle")


def _scan_spec():
    from sim.uuv.imitation.features import feature_spec
    from tests.support.hand_policy import IMITATION7

    return feature_spec(IMITATION7, "scan")
