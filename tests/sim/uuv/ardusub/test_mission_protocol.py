"""The front-seat's mission protocol (sim.uuv.ardusub.mission_server) answered as ArduSub SITL 4.7.0-dev answers it.

Each expectation below was read off the real firmware on loopback (vehicle time): the
vehicle asks with the deprecated MISSION_REQUEST, re-asks every second, cancels an upload
8 s after the last item, keeps home as seq 0, streams MISSION_CURRENT with SYS_STATUS.
"""

from __future__ import annotations

import math
import os

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.mission_server import MAX_ITEMS  # noqa: E402
from tests.sim.uuv.ardusub.test_bare_frontseat import LAUNCH, Bare  # noqa: E402

pytestmark = [pytest.mark.integration]

mav = mavutil.mavlink
MISSION, FENCE, RALLY, ALL = 0, 1, 2, 255
WAYPOINT, REL_ALT_INT = mav.MAV_CMD_NAV_WAYPOINT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT


def home_degE7(b: Bare) -> tuple[int, int]:
    lat, lon = b.fs.frame.to_latlon(*LAUNCH)
    return int(round(lat * 1e7)), int(round(lon * 1e7))


def expect(b: Bare, kind: str | list[str], timeout: float = 2.0, **fields):
    """The next message of ``kind`` (skipping the others); its fields must match ``fields``."""
    msg = b.gcs.recv_match(type=kind, blocking=True, timeout=timeout)
    assert msg is not None, f"no {kind}"
    for name, value in fields.items():
        assert getattr(msg, name) == value, (msg, name, value)
    return msg


def texts(b: Bare, vehicle_s: float = 1.0) -> list[str]:
    end = b.vehicle.t + vehicle_s
    out = []
    while b.vehicle.t < end:
        m = b.gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=0.05)
        if m is not None:
            out.append(m.text)
    return out


def send_item(b: Bare, seq: int, north_e7: int = 0, command: int = WAYPOINT, mission_type: int = MISSION, **kw):
    lat, lon = home_degE7(b)
    frame = kw.get("frame", mav.MAV_FRAME_GLOBAL if seq == 0 and mission_type == MISSION else REL_ALT_INT)
    b.gcs.mav.mission_item_int_send(
        1, 1, seq, frame, command, 0, 1, kw.get("p1", 0.0), 0, 0, 0, kw.get("x", lat + north_e7), lon,
        -2.0 if seq else 0.0, mission_type,
    )  # fmt: skip


def upload(b: Bare, norths: list[int], mission_type: int = MISSION, command: int = WAYPOINT) -> int:
    """Answer each MISSION_REQUEST as a ground station does; the MISSION_ACK's result."""
    b.drain()
    b.gcs.mav.mission_count_send(1, 1, len(norths), mission_type)
    while True:
        m = b.gcs.recv_match(type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"], blocking=True, timeout=2)
        assert m is not None
        assert m.get_type() != "MISSION_REQUEST_INT", "ArduSub asks with MISSION_REQUEST"
        if m.get_type() == "MISSION_ACK":
            assert m.mission_type == mission_type
            return int(m.type)
        send_item(b, m.seq, norths[m.seq], command, mission_type)


def test_upload_download_and_home_as_seq_0():
    with Bare(speedup=10, ekf_ready_s=0.0) as b:
        # at boot the mission is home alone
        b.drain()
        b.gcs.mav.mission_request_list_send(1, 1, MISSION)
        expect(b, "MISSION_COUNT", count=1, mission_type=MISSION)

        b.drain()
        assert upload(b, [12345, 500, 1000]) == mav.MAV_MISSION_ACCEPTED
        assert "Flight plan received" in texts(b, 0.5)
        lat, lon = home_degE7(b)

        b.gcs.mav.mission_request_list_send(1, 1, MISSION)
        expect(b, "MISSION_COUNT", count=3)
        got = []
        for seq in range(3):
            b.gcs.mav.mission_request_int_send(1, 1, seq, MISSION)
            got.append(expect(b, "MISSION_ITEM_INT", seq=seq, autocontinue=1, current=0))
        b.gcs.mav.mission_ack_send(1, 1, mav.MAV_MISSION_ACCEPTED, MISSION)
        assert (got[0].x, got[0].y, got[0].frame) == (lat, lon, mav.MAV_FRAME_GLOBAL)  # home, not what was sent
        relative = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT  # uploaded as ..._INT, read back as ArduSub stores it
        assert [(m.x, m.y, m.z, m.frame, m.command) for m in got[1:]] == [
            (lat + 500, lon, -2.0, relative, WAYPOINT),
            (lat + 1000, lon, -2.0, relative, WAYPOINT),
        ]
        assert len(b.fs.mission_items) == 3

        # the deprecated request is answered with MISSION_ITEM (float degrees) and a warning
        b.gcs.mav.mission_request_send(1, 1, 2, MISSION)
        item = expect(b, "MISSION_ITEM", seq=2)
        assert item.x == pytest.approx((lat + 1000) * 1e-7, abs=1e-6)
        assert "got MISSION_REQUEST; use MISSION_REQUEST_INT!" in texts(b, 0.5)

        # past the end: the count again, then INVALID_SEQUENCE
        b.gcs.mav.mission_request_int_send(1, 1, 7, MISSION)
        expect(b, "MISSION_COUNT", count=3)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_INVALID_SEQUENCE)

        # MISSION_ITEM uploads work too, with a one-time warning
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, 3, MISSION)
        home = b.fs.frame.to_latlon(*LAUNCH)
        for seq, command in enumerate((WAYPOINT, WAYPOINT, mav.MAV_CMD_NAV_LOITER_TIME)):
            expect(b, "MISSION_REQUEST", seq=seq)
            b.gcs.mav.mission_item_send(
                1, 1, seq, 3, command, 0, 1, 60.0, 15.0, 0, 0, home[0] + 1e-4 * seq, home[1], -1.0
            )
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_ACCEPTED)
        assert b.fs.missions.mission[1].x == pytest.approx(lat + 1000, abs=50)  # float32 degrees

        # a download gives back what AP_Mission keeps: no acceptance radius, LOITER_TIME clockwise
        for seq, params in ((1, (60.0, 0.0, 0.0, 0.0)), (2, (60.0, 0.0, 1.0, 0.0))):
            b.gcs.mav.mission_request_int_send(1, 1, seq, MISSION)
            got = expect(b, "MISSION_ITEM_INT", seq=seq)
            assert (got.param1, got.param2, got.param3, got.param4) == params


def test_bad_uploads_are_answered_as_ardusub_answers_them():
    with Bare(speedup=10, ekf_ready_s=0.0) as b:
        assert upload(b, [0, 500, 1000]) == mav.MAV_MISSION_ACCEPTED

        # out of sequence: INVALID_SEQUENCE, and the vehicle still wants the item it asked for
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, 3, MISSION)
        expect(b, "MISSION_REQUEST", seq=0)
        send_item(b, 2, 1000)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_INVALID_SEQUENCE)
        expect(b, "MISSION_REQUEST", seq=0)
        send_item(b, 0)
        expect(b, "MISSION_REQUEST", seq=1)

        # an unknown command ends the upload with UNSUPPORTED; items written so far stay, the old ones behind
        send_item(b, 1, command=999)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_UNSUPPORTED)
        send_item(b, 2, 1000)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_ERROR)  # no upload in progress
        b.gcs.mav.mission_request_list_send(1, 1, MISSION)
        expect(b, "MISSION_COUNT", count=3)

        # a latitude out of range, a frame AP_Mission does not take
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        expect(b, "MISSION_REQUEST", seq=0)
        send_item(b, 0, x=950_000_000)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_INVALID_PARAM5_X)
        b.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        expect(b, "MISSION_REQUEST", seq=0)
        send_item(b, 0, frame=mav.MAV_FRAME_LOCAL_NED)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_UNSUPPORTED_FRAME)

        # too many items; a count of 0 empties the mission, home included
        b.gcs.mav.mission_count_send(1, 1, MAX_ITEMS + 1, MISSION)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_NO_SPACE)
        assert upload(b, []) == mav.MAV_MISSION_ACCEPTED
        b.gcs.mav.mission_request_list_send(1, 1, MISSION)
        expect(b, "MISSION_COUNT", count=0)

        # mission_type ALL is not a list ArduSub keeps
        b.gcs.mav.mission_request_list_send(1, 1, ALL)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_UNSUPPORTED, mission_type=ALL)


def test_a_stalled_upload_is_asked_again_each_second_then_cancelled_after_8_s():
    with Bare(speedup=10, ekf_ready_s=0.0) as b:
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        t0 = b.vehicle.t
        requests, ack, text = [], None, []
        while ack is None and b.vehicle.t - t0 < 12:
            m = b.gcs.recv_match(type=["MISSION_REQUEST", "MISSION_ACK", "STATUSTEXT"], blocking=True, timeout=0.1)
            if m is None:
                continue
            if m.get_type() == "MISSION_REQUEST":
                requests.append(m.seq)
            elif m.get_type() == "MISSION_ACK":
                ack = (m.type, b.vehicle.t - t0)
            else:
                text.append(m.text)
        assert ack is not None and ack[0] == mav.MAV_MISSION_OPERATION_CANCELLED
        assert 7.5 < ack[1] < 9.5
        assert set(requests) == {0} and 7 <= len(requests) <= 10  # ArduSub SITL: 8 in 8 s
        assert "Mission upload timeout" in text + texts(b, 0.5)


def test_fence_and_rally_lists_and_clear_all():
    with Bare(speedup=10, ekf_ready_s=0.0) as b:
        for mission_type, command, text in ((FENCE, 5001, "Fence Indexed OK"), (RALLY, 5100, None)):
            b.drain()
            b.gcs.mav.mission_request_list_send(1, 1, mission_type)
            expect(b, "MISSION_COUNT", count=0, mission_type=mission_type)
            assert upload(b, [0, 300, 600], mission_type, command) == mav.MAV_MISSION_ACCEPTED
            if text:
                assert text in texts(b, 0.5)
            b.gcs.mav.mission_request_list_send(1, 1, mission_type)
            expect(b, "MISSION_COUNT", count=3, mission_type=mission_type)
            assert upload(b, [0], mission_type, WAYPOINT) == mav.MAV_MISSION_UNSUPPORTED  # not a fence/rally item
            b.gcs.mav.mission_clear_all_send(1, 1, mission_type)
            expect(b, "MISSION_ACK", type=mav.MAV_MISSION_ACCEPTED, mission_type=mission_type)
            b.gcs.mav.mission_request_list_send(1, 1, mission_type)
            expect(b, "MISSION_COUNT", count=0, mission_type=mission_type)

        # clearing the mission during its upload cancels the upload
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, 2, MISSION)
        expect(b, "MISSION_REQUEST", seq=0)
        b.gcs.mav.mission_clear_all_send(1, 1, MISSION)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_ACCEPTED)
        b.gcs.mav.mission_request_list_send(1, 1, MISSION)
        expect(b, "MISSION_COUNT", count=0)


def test_mission_current_streams_with_sys_status_and_follows_set_current():
    with Bare(speedup=20, ekf_ready_s=0.0) as b:
        seen = b.collect(10.0)
        assert abs(seen["MISSION_CURRENT"] - seen["SYS_STATUS"]) <= 1 and 17 <= seen["MISSION_CURRENT"] <= 23
        expect(b, "MISSION_CURRENT", seq=0, total=0, mission_state=mav.MISSION_STATE_NO_MISSION, mission_mode=0)

        assert upload(b, [0, 300, 600, 900]) == mav.MAV_MISSION_ACCEPTED
        expect(b, "MISSION_CURRENT", seq=0, total=3, mission_state=mav.MISSION_STATE_NOT_STARTED)

        b.drain()
        b.gcs.mav.mission_set_current_send(1, 1, 2)  # no acknowledgement, a MISSION_CURRENT at once
        expect(b, "MISSION_CURRENT", timeout=0.1, seq=2, total=3)
        b.gcs.mav.mission_set_current_send(1, 1, 9)  # no such item: nothing changes
        assert b.command(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 9) == mav.MAV_RESULT_DENIED
        expect(b, "MISSION_CURRENT", seq=2)
        assert b.command(mav.MAV_CMD_DO_SET_MISSION_CURRENT, 1) == mav.MAV_RESULT_ACCEPTED
        expect(b, "MISSION_CURRENT", seq=1)

        b.gcs.mav.mission_clear_all_send(1, 1, MISSION)
        expect(b, "MISSION_CURRENT", seq=0, total=0, mission_state=mav.MISSION_STATE_NO_MISSION)


def test_auto_flies_the_mission_and_reports_each_item_reached():
    with Bare(speedup=40, ekf_ready_s=0.0) as b:
        # home, a waypoint 20 m north at 2 m, a DO_CHANGE_SPEED (passed over), a 5 s loiter 20 m east of it
        lat, lon = home_degE7(b)
        north20 = int(round(20 / 111_200 * 1e7))
        items = [(WAYPOINT, lat, lon, 0.0, 0.0), (WAYPOINT, lat + north20, lon, -2.0, 0.0)]
        items += [(mav.MAV_CMD_DO_CHANGE_SPEED, 0, 0, 0.0, 1.0)]
        items += [(mav.MAV_CMD_NAV_LOITER_TIME, lat + north20, lon + int(round(20 / 74_900 * 1e7)), -2.0, 5.0)]
        b.drain()
        b.gcs.mav.mission_count_send(1, 1, len(items), MISSION)
        for _ in items:
            seq = expect(b, "MISSION_REQUEST").seq
            command, x, y, z, p1 = items[seq]
            b.gcs.mav.mission_item_int_send(1, 1, seq, 3 if seq else 0, command, 0, 1, p1, 0, 0, 0, x, y, z)
        expect(b, "MISSION_ACK", type=mav.MAV_MISSION_ACCEPTED)

        assert b.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == mav.MAV_RESULT_ACCEPTED
        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, 3) == mav.MAV_RESULT_ACCEPTED  # AUTO
        events = []
        t0 = b.vehicle.t
        while b.vehicle.t - t0 < 120 and (not events or events[-1] != ("state", mav.MISSION_STATE_COMPLETE)):
            m = b.gcs.recv_match(
                type=["MISSION_ITEM_REACHED", "STATUSTEXT", "MISSION_CURRENT"], blocking=True, timeout=1
            )
            if m is None:
                continue
            if m.get_type() == "MISSION_ITEM_REACHED":
                events.append(("reached", m.seq, round(b.vehicle.t - t0)))
            elif m.get_type() == "STATUSTEXT" and m.text.startswith(("Mission:", "Reached")):
                events.append(("text", m.text))
            elif m.get_type() == "MISSION_CURRENT" and (not events or events[-1] != ("state", m.mission_state)):
                events.append(("state", m.mission_state))
        kinds = [e[:2] for e in events if e[0] != "state"]
        assert kinds == [
            ("text", "Mission: 1 WP"), ("reached", 1), ("text", "Reached command #1"),
            ("text", "Mission: 3 LoitTime"), ("reached", 3),
        ], events  # fmt: skip
        assert events[-1] == ("state", mav.MISSION_STATE_COMPLETE)
        reached = {e[1]: e[2] for e in events if e[0] == "reached"}
        assert reached[3] - reached[1] >= 5  # 20 m and the 5 s loiter
        truth = b.vehicle.truth()
        # reached within 2 m; a vehicle that steers by heading and speed wanders a little over a 5 s loiter
        assert math.hypot(truth.north - 20, truth.east - 20) < 5 and abs(truth.depth - 2) < 1
        expect(b, "MISSION_CURRENT", seq=3, total=3, mission_state=mav.MISSION_STATE_COMPLETE)
