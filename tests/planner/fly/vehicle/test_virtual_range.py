"""The live-virtual range on a real loopback Zenoh bus: virtual sonar contacts and the virtual fuel gauge."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from bridge import keys
from planner.common.telemetry import VIRTUAL_BATTERY_ID, VehicleTelemetry
from planner.fly.vehicle.virtual_range import SENSOR_COMPONENT, VirtualRange, body_frd
from sim.uuv.geo import LocalFrame
from sim.uuv.mission import Rect, Triangle, Vehicle
from sim.uuv.sonar import sense
from tests.support.livebus import VEHICLE, FakeVehicle, Listener, bus, decoded, telemetry_of
from tests.support.loopback import no_new_threads, wait_until
from tests.support.uuvworld import mission as small_mission

pytestmark = [pytest.mark.integration]

U = [0.5]


@pytest.fixture(autouse=True)
def no_leftover_threads():
    with no_new_threads():
        yield


def _virtual(items):
    """The raw-stream samples marked virtual."""
    return [x for x in items if x[2] == keys.VIRTUAL_ATTACHMENT]


def _mission(**vehicle):
    """A barrier 40 m north of the centre across the way, a small obstacle 60 m east."""
    return small_mission(
        barriers=(Rect("B", 0.0, 50.0, 200.0, 20.0),),
        obstacles=(Triangle("O", 60.0, -10.0, 20.0),),
        vehicle=Vehicle(**{"battery_wh": 1000.0, **vehicle}),
    )


def _latest_pose_ms(mission, frames) -> int | None:
    pose = telemetry_of(mission, frames).pose
    return None if pose is None else pose.time_ms


def test_barriers_ahead_in_range_are_reported_as_body_frd_contacts_that_round_trip():
    m = _mission()
    with bus() as s:
        raw, virtual = Listener(s, keys.raw(VEHICLE)), Listener(s, keys.virtual(VEHICLE, "*"))
        vehicle = FakeVehicle(s, m)
        with VirtualRange(s, VEHICLE, m, U) as vr:
            scen = vr.scen
            poses = [  # (time_ms, east, north, heading): what each should see
                (1000, 0.0, 0.0, 0.0),  # heading north: the barrier 40 m ahead, not the obstacle abeam
                (2000, 0.0, 0.0, math.pi),  # heading south: the barrier is behind
                (3000, 0.0, -200.0, 0.0),  # the barrier ahead but 240 m off, beyond the 100 m range
                (4000, 0.0, 0.0, math.pi / 2),  # heading east: the obstacle ahead, the barrier abeam
                (5000, 30.0, 45.0, 0.5),  # inside the barrier: reported although it is close
            ]
            seen: dict[int, set[int]] = {}
            for n, (t, east, north, heading) in enumerate(poses, 1):
                vehicle.pose(t, east, north, heading)
                wait_until(lambda n=n: vr.stats["poses"] == n, what=f"pose {n}")
                sent = vr.stats["contacts_sent"]
                wait_until(lambda c=sent: len(_virtual(raw.items())) == c, what="the contacts on the raw stream")
                # the listener is a subscriber of its own: the pose may reach it after the range saw it
                wait_until(lambda t=t: _latest_pose_ms(m, raw.items()) == t, what=f"pose {n} on the raw stream")
                # the consumer (a back-seat) reads the stream up to here and converts the contacts back
                tel = telemetry_of(m, raw.items())
                pose = tel.pose
                assert pose is not None and pose.time_ms == t
                truth = sense(
                    np.array([pose.east]),
                    np.array([pose.north]),
                    np.array([pose.heading]),
                    scen.obstacle_edges,
                    scen.barriers,
                    m.vehicle,
                )
                seen[t] = set(tel.recent_contacts(t))
                assert seen[t] == set(np.flatnonzero(truth.detected[0]).tolist())
                for j, contact in tel.recent_contacts(t).items():
                    assert contact.east == pytest.approx(truth.x[0, j], abs=1e-4)
                    assert contact.north == pytest.approx(truth.y[0, j], abs=1e-4)
            stats = vr.stats
        vehicle.close()
        frames = _virtual(raw.items())
        json_items = virtual.items(keys.virtual(VEHICLE, "OBSTACLE_DISTANCE_3D"))
        raw.close()
        virtual.close()
    barrier = len(m.obstacles)  # contacts are numbered obstacles first, then barriers
    assert seen == {1000: {barrier}, 2000: set(), 3000: set(), 4000: {0}, 5000: {barrier}}
    msgs = decoded(frames)
    assert stats["contacts_sent"] == 3
    assert [msg.get_type() for msg in msgs] == ["OBSTACLE_DISTANCE_3D"] * 3
    assert [(msg.get_srcSystem(), msg.get_srcComponent()) for msg in msgs] == [(1, SENSOR_COMPONENT)] * 3
    assert [msg.get_seq() for msg in msgs] == [0, 1, 2]  # its own sequence, not the vehicle's
    first = msgs[0]
    assert (first.frame, first.sensor_type, first.obstacle_id, first.time_boot_ms) == (12, 1, barrier, 1000)
    assert (first.min_distance, first.max_distance) == (0.0, m.vehicle.sonar_range_m)
    assert first.x == pytest.approx(40.0, abs=0.05) and abs(first.y) < 0.05 and first.z == 0.0  # ahead, not right
    logged = [json.loads(p) for _, p, _ in json_items]
    assert [(d["obstacle_id"], d["time_boot_ms"]) for d in logged] == [(barrier, 1000), (0, 4000), (barrier, 5000)]
    assert stats["virtual_skipped"] == 3  # its own frames came back and were not taken for the vehicle's


def test_body_frd_is_forward_and_right_of_the_heading():
    from planner.common.telemetry import Pose

    east_facing = Pose(0, 10.0, 20.0, 2.0, math.pi / 2, 0)
    assert body_frd(east_facing, 15.0, 20.0) == pytest.approx((5.0, 0.0))  # 5 m east: ahead
    assert body_frd(east_facing, 10.0, 17.0) == pytest.approx((0.0, 3.0))  # 3 m south: to starboard


def test_the_fuel_gauge_counts_the_packs_draw_from_begin_against_the_scenario_charge():
    m = _mission(start_battery=0.3)  # 300 Wh of 1000 Wh at the scenario's start
    with bus() as s:
        raw, virtual = Listener(s, keys.raw(VEHICLE)), Listener(s, keys.virtual(VEHICLE, "BATTERY_STATUS"))
        vehicle = FakeVehicle(s, m)
        with VirtualRange(s, VEHICLE, m, U) as vr:
            vehicle.battery(1000)  # drawn before the scenario: not the scenario's
            wait_until(lambda: vr.stats["pack_reports"] == 1, what="the pack's report")
            assert vr.stats["gauge_sent"] == 0
            vr.begin()
            vehicle.battery(1000)
            vehicle.battery(1360)  # 10 Wh more
            wait_until(lambda: vr.stats["gauge_sent"] == 2, what="two gauge reports")
            assert vr.used_wh == pytest.approx(10.0)
            # the listener has its own subscriber: wait for the pack's three reports and the two gauges
            wait_until(lambda: len(raw.items()) == 5, what="the first range's five raw frames")
        n_first = len(raw.items())
        with VirtualRange(s, VEHICLE, m, U) as vr:  # a pack that counts only charge: mAh times its voltage
            vehicle.battery(-1, mah=100)
            wait_until(lambda: vr.stats["pack_reports"] == 1, what="the pack's report")
            vr.begin()
            vehicle.battery(-1, mah=776)  # 676 mAh at 14.8 V: 10.0048 Wh
            wait_until(lambda: vr.stats["gauge_sent"] == 1, what="a gauge report")
        # sent is not yet received: wait for every gauge frame to reach the listeners
        wait_until(lambda: len(decoded(_virtual(raw.items()))) == 3, what="three gauge frames on the raw stream")
        wait_until(
            lambda: len(virtual.payloads(keys.virtual(VEHICLE, "BATTERY_STATUS"))) == 3, what="three gauge copies"
        )
        vehicle.close()
        frames, logged = raw.items(), [json.loads(p) for p in virtual.payloads(keys.virtual(VEHICLE, "BATTERY_STATUS"))]
        raw.close()
        virtual.close()
    gauges = decoded(_virtual(frames))
    assert [g.id for g in gauges] == [VIRTUAL_BATTERY_ID] * 3
    assert [g.energy_consumed for g in gauges] == [0, 360, 360]
    assert [g.battery_remaining for g in gauges] == [30, 29, 29]
    assert [g.current_consumed for g in gauges] == [-1, -1, 676]
    assert gauges[0].voltages[0] == 14800 and gauges[0].current_battery == 500  # the rest is the pack's
    assert [d["energy_consumed"] for d in logged] == [0, 360, 360]  # logged apart from the pack's
    # a back-seat reading the gauge instead of the pack; the pack's own report is still there beside it
    both = telemetry_of(m, frames[:n_first], battery_id=VIRTUAL_BATTERY_ID)
    assert both.pack is not None and both.pack.energy_consumed == 1360 and both.energy_hj == 360


def test_a_contact_overtaken_by_a_newer_pose_is_placed_from_its_own_pose():
    """The bus may deliver the vehicle's next pose before the contacts computed from the previous one."""
    m = _mission()
    tel = VehicleTelemetry(LocalFrame(m.origin_lat, m.origin_lon))
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    poses = []
    for t, north, heading in ((1000, 0.0, 0.0), (1250, 0.5, 0.2)):
        lat, lon = tel.frame.to_latlon(0.0, north)
        tel.add(mavlink.MAVLink_attitude_message(t, 0.0, 0.0, heading, 0.0, 0.0, 0.0))
        tel.add(
            mavlink.MAVLink_global_position_int_message(t, round(lat * 1e7), round(lon * 1e7), 0, -2000, 0, 0, 0, 0)
        )
        poses.append(tel.pose)
    first = poses[0]
    assert first is not None and first.time_ms == 1000 and tel.pose is not None and tel.pose.time_ms == 1250
    x, y = body_frd(first, 0.0, 40.0)
    msg = mavlink.MAVLink_obstacle_distance_3d_message(1000, 1, 12, 1, x, y, 0.0, 0.0, 100.0)
    frame = mavlink.MAVLink(None).parse_buffer(msg.pack(mav))
    tel.add(frame[0])
    contact = tel.contacts[1]
    assert (contact.east, contact.north) == (pytest.approx(0.0, abs=1e-4), pytest.approx(40.0, abs=1e-4))
