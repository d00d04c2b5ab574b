"""The simulated front-seat over real MAVLink on loopback (no bus in between)."""

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import sim.uuv  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from sim.uuv.autonomy import Autonomy, Observation  # noqa: E402
from sim.uuv.interface import battery_fraction, encode_command  # noqa: E402
from sim.uuv.replay import score_track  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402

pytestmark = [pytest.mark.integration]

EXAMPLES = Path(__file__).resolve().parents[4] / "examples"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Vehicle:
    """A FrontSeat serving in a thread, closed on exit."""

    def __init__(self, mission, u, **kw):
        self.port = free_udp_port()
        self.fs = FrontSeat(mission, u, f"udpin:127.0.0.1:{self.port}", **kw)
        self.thread = threading.Thread(target=self.fs.serve, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.fs.stop()
        self.thread.join(timeout=5)
        self.fs.close()


def connect(port):
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=1, source_component=191, dialect="ardupilotmega"
    )
    gcs.mav.heartbeat_send(18, 8, 0, 0, 0)
    assert gcs.wait_heartbeat(timeout=5) is not None
    return gcs


def command(gcs, cmd, p1=0.0, p2=0.0):
    gcs.mav.command_long_send(1, 1, cmd, 0, p1, p2, 0, 0, 0, 0, 0)
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
    assert ack is not None and ack.command == cmd
    return ack.result


def fly_lockstep(mission, u, gcs, fs, limit_s=60.0):
    """The batch autonomy flying over MAVLink, step by step; returns (track, autonomy)."""
    scen = make_scenarios(mission, np.asarray(u)[None, :])
    autonomy = Autonomy(scen)
    start_wh = scen.battery0 * mission.vehicle.battery_wh
    k = scen.obstacles.shape[1] + scen.barriers.shape[1]
    tick, track, answered, ended_at = {}, [], -1, None
    t0 = time.monotonic()
    while time.monotonic() - t0 < limit_s:
        if fs.ended and ended_at is None:
            ended_at = time.monotonic()
        if ended_at and time.monotonic() - ended_at > 0.3:
            break
        msg = gcs.recv_match(blocking=True, timeout=0.1)
        if msg is None:
            continue
        kind = msg.get_type()
        if kind == "OBSTACLE_DISTANCE_3D":
            tick.setdefault("c", {})[msg.obstacle_id] = (msg.y, msg.x)
        elif kind in ("LOCAL_POSITION_NED", "ATTITUDE", "BATTERY_STATUS"):
            tick[kind] = msg
        elif kind == "SYSTEM_TIME":
            ms = msg.time_boot_ms
            if ms > answered and {"LOCAL_POSITION_NED", "ATTITUDE", "BATTERY_STATUS"} <= set(tick):
                lp, att, bat = tick["LOCAL_POSITION_NED"], tick["ATTITUDE"], tick["BATTERY_STATUS"]
                track.append((ms / 1000, lp.y, lp.x, att.yaw, bat.energy_consumed, float(lp.z == 0)))
                cx, cy, seen = np.zeros((1, k)), np.zeros((1, k)), np.zeros((1, k), bool)
                for j, (east, north) in tick.get("c", {}).items():
                    cx[0, j], cy[0, j], seen[0, j] = east, north, True
                battery = battery_fraction(start_wh, np.array([bat.energy_consumed]), mission.vehicle.battery_wh)
                obs = Observation(
                    ms / 1000,
                    np.array([lp.y]),
                    np.array([lp.x]),
                    np.array([att.yaw]),
                    battery,
                    cx,
                    cy,
                    np.zeros((1, k)),
                    seen,
                )
                cmd = autonomy.step(obs, mission.dt, np.ones(1, bool))
                vx, vy, vz, yaw = encode_command(cmd.heading, cmd.speed, cmd.surface)
                gcs.mav.set_position_target_local_ned_send(
                    ms, 1, 1, 1, 2503, 0, 0, 0, float(vx[0]), float(vy[0]), float(vz[0]), 0, 0, 0, float(yaw[0]), 0
                )
                answered = ms
            tick = {}
    return np.array(track), autonomy


def test_lockstep_flight_over_mavlink_scores_exactly_as_the_batch():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(9).random((40, m.dim))
    batch = sim.uuv.simulate(m, X)
    for i in np.flatnonzero(batch.valid)[:3]:
        with Vehicle(m, X[i]) as v:
            gcs = connect(v.port)
            assert command(gcs, 176, 1, 4) == 0 and command(gcs, 400, 1) == 0  # GUIDED, armed
            track, autonomy = fly_lockstep(m, X[i], gcs, v.fs)
            gcs.close()
            assert v.fs.ended and v.fs.t / 2.0 > 100  # flew the whole run, many times real time
        scores = score_track(m, X[i], track, autonomy.wp_aborted[0], int(autonomy.return_reason[0]))
        np.testing.assert_array_equal(scores, batch.scores[i])


def test_setpoints_need_guided_and_a_velocity_yaw_mask():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    u = np.random.default_rng(9).random((40, m.dim))[
        np.flatnonzero(sim.uuv.simulate(m, np.random.default_rng(9).random((40, m.dim))).valid)[0]
    ]
    with Vehicle(m, u) as v:
        gcs = connect(v.port)
        assert command(gcs, 400, 1) == 0
        gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, 2503, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, 0)  # MANUAL
        assert command(gcs, 176, 1, 4) == 0
        gcs.mav.set_position_target_local_ned_send(0, 1, 1, 1, 3576, 10, 10, 0, 0, 0, 0, 0, 0, 0, 0, 0)  # position
        gcs.mav.set_position_target_local_ned_send(0, 1, 1, 6, 2503, 0, 0, 0, 1.0, 0, 0, 0, 0, 0, 0, 0)  # bad frame
        assert command(gcs, 9999) == 3  # unsupported command: MAV_RESULT_UNSUPPORTED
        assert v.fs.stats.ignored == 3 and v.fs.stats.setpoints == 0
        gcs.close()


def test_failsafe_surfaces_and_holds_without_a_backseat():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(9).random((40, m.dim))
    u = X[np.flatnonzero(sim.uuv.simulate(m, X).valid)[0]]
    with Vehicle(m, u, failsafe_s=0.3) as v:
        gcs = connect(v.port)
        assert command(gcs, 176, 1, 4) == 0 and command(gcs, 400, 1) == 0
        fix = None
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline and fix is None:
            msg = gcs.recv_match(type="GPS_RAW_INT", blocking=True, timeout=0.5)
            if msg is not None and msg.fix_type == 3:
                fix = msg
        gcs.close()
        assert fix is not None and v.fs.stats.failsafes >= 1  # on the surface: a GPS fix
        assert "failsafe" in " ".join(v.fs.stats.log)


def test_invalid_scenario_is_refused():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(1).random((200, m.dim))
    bad = X[np.flatnonzero(~sim.uuv.simulate(m, X).valid)[0]]
    with pytest.raises(ValueError, match="scenario: invalid"):
        FrontSeat(m, bad, f"udpin:127.0.0.1:{free_udp_port()}")


CLIENT = r"""
import json, os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil
port = int(sys.argv[1])
c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255, source_component=190,
                               dialect="ardupilotmega")
c.mav.heartbeat_send(6, 8, 0, 0, 0)
c.wait_heartbeat(timeout=5)
items = [(47.7001, -122.6201), (47.7010, -122.6190), (47.7015, -122.6180)]
c.mav.mission_count_send(1, 1, len(items))
sent = 0
while True:
    m = c.recv_match(type=["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"], blocking=True, timeout=3)
    if m is None or m.get_type() == "MISSION_ACK":
        break
    lat, lon = items[m.seq]
    c.mav.mission_item_int_send(1, 1, m.seq, 6, 16, 0, 1, 0, 0, 0, 0, int(lat * 1e7), int(lon * 1e7), -2.0)
    sent += 1
ack = m.type if m is not None else -1
def cmd(n, p1=0, p2=0):
    c.mav.command_long_send(1, 1, n, 0, p1, p2, 0, 0, 0, 0, 0)
    a = c.recv_match(type="COMMAND_ACK", blocking=True, timeout=3)
    return a.result if a else -1
mode, arm = cmd(176, 1, 4), cmd(400, 1)
first = c.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=3)
north0 = first.x
last = first
t0 = time.time()
while time.time() - t0 < 3:
    c.mav.set_position_target_local_ned_send(0, 1, 1, 1, 2503, 0, 0, 0, 2.0, 0.0, 0.5, 0, 0, 0, 0.0, 0)
    m = c.recv_match(type="LOCAL_POSITION_NED", blocking=True, timeout=0.2)
    last = m or last
print(json.dumps({"sent": sent, "ack": ack, "mode": mode, "arm": arm, "moved_north": last.x - north0}))
"""


def test_an_independent_mavlink_client_uploads_a_mission_arms_and_sees_the_vehicle_move():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    X = np.random.default_rng(9).random((40, m.dim))
    u = X[np.flatnonzero(sim.uuv.simulate(m, X).valid)[0]]
    with Vehicle(m, u, lockstep=False, speedup=50.0) as v:
        out = subprocess.run([sys.executable, "-c", CLIENT, str(v.port)], capture_output=True, text=True, timeout=60)
        assert out.returncode == 0, out.stderr
        report = json.loads(out.stdout.strip().splitlines()[-1])
        assert report["sent"] == 3 and report["ack"] == 0 and len(v.fs.mission_items) == 3
        assert report["mode"] == 0 and report["arm"] == 0
        assert report["moved_north"] > 20.0  # 3 s at 50x: ~150 s of simulated travel at up to 2 m/s
