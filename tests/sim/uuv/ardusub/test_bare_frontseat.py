"""The bare front-seat (``FrontSeat(bare=True)``): an ArduSub as a client meets it, over real MAVLink on loopback.

The figures it must reproduce were measured on ArduSub SITL 4.7.0-dev (see sim.uuv.ardusub.streams,
sim.uuv.ardusub.ekf, sim.uuv.ardusub.guided): default stream rates, GUIDED refused until the position
estimate is ready, velocity targets zeroed 3 s after the last one.
"""

from __future__ import annotations

import collections
import math
import os
import socket
import threading

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.depth import SURFACED_M  # noqa: E402
from sim.uuv.ardusub.ekf import FLAGS_BOOT, FLAGS_READY  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402
from tests.support.uuvworld import mission  # noqa: E402

pytestmark = [pytest.mark.integration]

mav = mavutil.mavlink
ACCEPTED, DENIED, FAILED = mav.MAV_RESULT_ACCEPTED, mav.MAV_RESULT_DENIED, mav.MAV_RESULT_FAILED
GUIDED, SURFACE, MANUAL = 4, 9, 19
VELOCITY, VELOCITY_YAW, POSITION = 3527, 2503, 3576
LAUNCH = (0.0, -800.0)  # uuvworld.mission()'s launch point, east/north of its origin


class Bare:
    """A bare FrontSeat serving in a thread and a ground station talking to it; all closed on exit."""

    def __init__(self, speedup: float = 20.0, ekf_ready_s: float = 1.0, sysid: int = 250, **kw):
        port = free_port(socket.SOCK_DGRAM)
        self.fs = FrontSeat(
            mission(), [0.5], f"udpin:127.0.0.1:{port}", bare=True, speedup=speedup, ekf_ready_s=ekf_ready_s, **kw
        )
        assert self.fs.bare is not None
        self.vehicle = self.fs.bare
        self.thread = threading.Thread(target=self.fs.serve, daemon=True)
        self.gcs = mavutil.mavlink_connection(
            f"udpout:127.0.0.1:{port}", source_system=sysid, source_component=190, dialect="ardupilotmega"
        )

    def __enter__(self) -> Bare:
        self.thread.start()
        self.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        assert self.gcs.wait_heartbeat(timeout=5) is not None
        return self

    def __exit__(self, *exc) -> None:
        self.fs.stop()
        self.thread.join(timeout=5)
        assert not self.thread.is_alive()
        self.fs.close()
        self.gcs.close()

    def drain(self) -> None:
        """Read what is queued: a client that stops reading loses datagrams (the ACK too) once its buffer fills."""
        while self.gcs.recv_match(blocking=False) is not None:
            pass

    def command(self, cmd: int, *params: float) -> int:
        p = [*params, *[0.0] * (7 - len(params))]
        self.drain()
        self.gcs.mav.command_long_send(1, 1, cmd, 0, *p)
        ack = self.gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=2)
        assert ack is not None and ack.command == cmd
        return int(ack.result)

    def collect(self, vehicle_s: float) -> collections.Counter:
        """Messages by type over the next ``vehicle_s`` vehicle seconds (after draining what was queued)."""
        self.drain()
        end = self.vehicle.t + vehicle_s
        seen: collections.Counter = collections.Counter()
        while self.vehicle.t < end:
            msg = self.gcs.recv_match(blocking=True, timeout=0.05)
            if msg is not None:
                seen[msg.get_type()] += 1
        return seen

    def wait_vehicle(self, t: float) -> None:
        wait_until(lambda: self.vehicle.t >= t, timeout=10, what=f"vehicle time {t}")

    def latest(self, kind: str, timeout: float = 2.0):
        self.drain()
        msg = self.gcs.recv_match(type=kind, blocking=True, timeout=timeout)
        assert msg is not None, kind
        return msg

    def guided_and_armed(self) -> None:
        self.wait_vehicle(self.vehicle.ekf.ready_s)
        assert self.command(mav.MAV_CMD_DO_SET_MODE, 1, GUIDED) == ACCEPTED
        assert self.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED

    def setpoint(self, mask: int, frame: int = mav.MAV_FRAME_LOCAL_NED, **v: float) -> None:
        g = v.get
        self.gcs.mav.set_position_target_local_ned_send(
            0, 1, 1, frame, mask, g("x", 0), g("y", 0), g("z", 0), g("vx", 0), g("vy", 0), g("vz", 0),
            g("ax", 0), 0, 0, g("yaw", 0), 0,
        )  # fmt: skip


def near(count: int, hz: float, seconds: float) -> bool:
    """A count over a window matches a rate, give or take a message at each edge and 10 %."""
    return abs(count - hz * seconds) <= 1.5 + 0.1 * hz * seconds


def test_streams_at_ardusub_default_rates_without_sonar_and_as_asked():
    with Bare(speedup=20, ekf_ready_s=0.0) as b:
        seen = b.collect(10.0)
        defaults = {"HEARTBEAT": 1, "ATTITUDE": 10, "VFR_HUD": 10, "GLOBAL_POSITION_INT": 3, "LOCAL_POSITION_NED": 3}
        defaults |= {"SYSTEM_TIME": 3, "BATTERY_STATUS": 3, "EKF_STATUS_REPORT": 3, "SYS_STATUS": 2, "GPS_RAW_INT": 2}
        for kind, hz in defaults.items():
            assert near(seen[kind], hz, 10.0), (kind, seen[kind])
        assert not {"OBSTACLE_DISTANCE", "OBSTACLE_DISTANCE_3D"} & set(seen)

        # per message: 1 Hz, off, back to the default; an id ArduSub cannot stream is denied
        assert b.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 1e6) == ACCEPTED
        assert near(b.collect(10.0)["ATTITUDE"], 1, 10.0)
        assert b.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, -1) == ACCEPTED
        assert b.collect(5.0)["ATTITUDE"] == 0
        assert b.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_ATTITUDE, 0) == ACCEPTED
        assert near(b.collect(5.0)["ATTITUDE"], 10, 5.0)
        assert b.command(mav.MAV_CMD_SET_MESSAGE_INTERVAL, mav.MAVLINK_MSG_ID_OBSTACLE_DISTANCE, 1e6) == DENIED

        # per group (no answer, as ArduSub): POSITION at 1 Hz, then everything off but the heartbeat
        b.gcs.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_POSITION, 1, 1)
        seen = b.collect(10.0)
        assert near(seen["GLOBAL_POSITION_INT"], 1, 10.0) and near(seen["LOCAL_POSITION_NED"], 1, 10.0)
        assert near(seen["ATTITUDE"], 10, 10.0)
        b.gcs.mav.request_data_stream_send(1, 1, mav.MAV_DATA_STREAM_ALL, 0, 0)
        b.wait_vehicle(b.vehicle.t + 1.0)  # what was on its way before the request
        seen = b.collect(5.0)
        assert set(seen) <= {"HEARTBEAT"}, seen

        # one message on request, streams off or not
        assert b.command(mav.MAV_CMD_REQUEST_MESSAGE, mav.MAVLINK_MSG_ID_GPS_RAW_INT) == ACCEPTED
        assert b.gcs.recv_match(type="GPS_RAW_INT", blocking=True, timeout=1) is not None
        assert b.command(mav.MAV_CMD_REQUEST_MESSAGE, 12345) == FAILED


def test_guided_is_refused_until_the_position_estimate_is_ready():
    with Bare(speedup=10, ekf_ready_s=15.0) as b:
        assert b.vehicle.t < 10.0, "the test must start well before the estimate is ready"
        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, GUIDED) == FAILED
        text = b.gcs.recv_match(type="STATUSTEXT", blocking=True, timeout=1)
        assert text is not None and text.text == "Mode change failed: GUIDED requires position"
        assert b.latest("EKF_STATUS_REPORT").flags == FLAGS_BOOT
        assert b.collect(2.0)["LOCAL_POSITION_NED"] == 0  # ArduSub sends none before
        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, 2) == ACCEPTED  # ALT_HOLD needs no position
        assert b.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 1) == ACCEPTED  # nor does arming
        assert b.command(mav.MAV_CMD_COMPONENT_ARM_DISARM, 0) == ACCEPTED
        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, 15) == FAILED  # no such mode
        assert b.fs.mode == 2 and not b.fs.armed

        b.wait_vehicle(15.0)
        assert b.latest("EKF_STATUS_REPORT").flags == FLAGS_READY
        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, GUIDED) == ACCEPTED
        hb = b.latest("HEARTBEAT")
        assert hb.custom_mode == GUIDED and hb.type == mav.MAV_TYPE_SUBMARINE
        assert hb.base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED and not hb.base_mode & 128


def test_a_velocity_setpoint_moves_the_vehicle_from_its_boot_point_and_lapses_after_3_s():
    with Bare(speedup=20, ekf_ready_s=1.0) as b:
        lp = b.latest("LOCAL_POSITION_NED")
        assert abs(lp.x) < 0.01 and abs(lp.y) < 0.01 and lp.z == 0.0  # the EKF origin is where it booted
        gp = b.latest("GLOBAL_POSITION_INT")
        lat, lon = LocalFrame(47.7, -122.6).to_latlon(*LAUNCH)
        assert abs(gp.lat - lat * 1e7) < 2 and abs(gp.lon - lon * 1e7) < 2 and gp.relative_alt == 0

        b.guided_and_armed()
        start = b.vehicle.truth()
        for _ in range(10):  # 1 m/s north-east, refreshed every vehicle second for 10 s
            b.setpoint(VELOCITY, vx=math.sqrt(0.5), vy=math.sqrt(0.5))
            b.wait_vehicle(b.vehicle.t + 1.0)
        moved = b.vehicle.truth()
        assert moved.north - start.north > 3.0 and moved.east - start.east > 2.0  # it turns from north first
        assert abs(moved.heading - math.pi / 4) < 0.1
        lp = b.latest("LOCAL_POSITION_NED")
        assert abs(lp.x - b.vehicle.truth().north) < 0.5 and abs(lp.y - b.vehicle.truth().east) < 0.5
        assert lp.vx > 0.3 and lp.vy > 0.3

        last = b.vehicle.target.received
        b.wait_vehicle(last + 2.5)
        assert b.vehicle.truth().speed > 0.8  # still obeyed
        b.wait_vehicle(last + 3.5)
        assert b.vehicle.target.vn == 0.0 and b.vehicle.target.ve == 0.0  # zeroed, as ArduSub does
        b.wait_vehicle(last + 15.0)
        assert b.vehicle.truth().speed < 0.1
        assert b.fs.armed and b.fs.mode == GUIDED and not b.fs.ended  # no referee, no self-disarm


def test_vz_dives_the_fix_is_lost_underwater_and_surface_mode_brings_it_up():
    with Bare(speedup=20, ekf_ready_s=1.0) as b:
        b.guided_and_armed()
        assert b.latest("GPS_RAW_INT").fix_type == mav.GPS_FIX_TYPE_3D_FIX
        for _ in range(6):  # 0.5 m/s down for 6 s
            b.setpoint(VELOCITY, vz=0.5)
            b.wait_vehicle(b.vehicle.t + 1.0)
        depth = b.vehicle.truth().depth
        assert 2.5 < depth < 3.6
        assert b.latest("GPS_RAW_INT").fix_type == mav.GPS_FIX_TYPE_NO_FIX
        assert abs(b.latest("GLOBAL_POSITION_INT").relative_alt + 1000 * b.vehicle.truth().depth) < 300
        assert abs(b.latest("LOCAL_POSITION_NED").z - b.vehicle.truth().depth) < 0.3
        b.wait_vehicle(b.vehicle.t + 5.0)  # lapsed: it holds its depth
        held = b.vehicle.truth().depth
        assert held < depth + 2.0 and abs(b.vehicle.truth().depth - held) < 0.01

        b.setpoint(POSITION, x=b.vehicle.truth().north, y=b.vehicle.truth().east, z=1.0)  # a depth target
        b.wait_vehicle(b.vehicle.t + 6.0)
        assert abs(b.vehicle.truth().depth - 1.0) < 0.01

        assert b.command(mav.MAV_CMD_DO_SET_MODE, 1, SURFACE) == ACCEPTED
        b.wait_vehicle(b.vehicle.t + 2.0)
        assert b.vehicle.truth().depth <= SURFACED_M  # at the surface: where ArduSub's at_surface begins
        assert b.latest("GPS_RAW_INT").fix_type == mav.GPS_FIX_TYPE_3D_FIX
        # at the surface SURFACE hands over to ALT_HOLD by itself, as ArduSub's does (mode_surface.cpp)
        assert b.latest("HEARTBEAT").custom_mode == 2 and b.fs.armed


def test_setpoints_arduSub_drops_change_nothing():
    with Bare(speedup=20, ekf_ready_s=1.0) as b:
        b.wait_vehicle(1.0)
        b.setpoint(VELOCITY, vx=1.0)  # not in GUIDED yet
        wait_until(lambda: b.fs.stats.ignored == 1, what="the set-point outside GUIDED ignored")
        b.guided_and_armed()
        b.setpoint(0, vx=1.0)  # acceleration not ignored
        b.setpoint(VELOCITY, frame=mav.MAV_FRAME_GLOBAL, vx=1.0)  # a frame ArduSub drops
        b.setpoint(0x7 | 0x38 | 0x1C0, yaw=1.0)  # neither position nor velocity
        wait_until(lambda: b.fs.stats.ignored == 4, what="the invalid set-points ignored")
        before = b.vehicle.truth()
        b.wait_vehicle(b.vehicle.t + 3.0)
        assert b.fs.stats.setpoints == 0 and b.vehicle.truth().speed < 0.01
        assert math.hypot(b.vehicle.truth().north - before.north, b.vehicle.truth().east - before.east) < 0.01

        # BODY_NED is relative to the bow: "forward" goes the way the vehicle points
        b.setpoint(VELOCITY_YAW, frame=mav.MAV_FRAME_BODY_NED, vx=1.0, yaw=before.heading)
        wait_until(lambda: b.fs.stats.setpoints == 1, what="the BODY_NED set-point taken")
        b.wait_vehicle(b.vehicle.t + 2.5)
        after = b.vehicle.truth()
        course = math.atan2(after.east - before.east, after.north - before.north)
        assert abs(math.remainder(course - before.heading, math.tau)) < 0.05


def test_the_gcs_failsafe_disarms_once_the_ground_station_heartbeat_stops():
    with Bare(speedup=20, ekf_ready_s=1.0, sysid=255) as b:
        b.guided_and_armed()
        b.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        armed_at = b.vehicle.t
        b.wait_vehicle(armed_at + 3.0)
        assert b.fs.armed
        wait_until(lambda: not b.fs.armed, timeout=2, what="the GCS failsafe")
        assert b.vehicle.t - armed_at > 5.0 and b.fs.stats.failsafes == 1


def test_parameters_a_ground_station_sets_act_on_the_vehicle():
    with Bare(speedup=8, ekf_ready_s=1.0, sysid=255) as b:

        def param_set(name: str, value: float) -> float:
            b.drain()
            b.gcs.mav.param_set_send(1, 1, name.encode(), value, mav.MAV_PARAM_TYPE_REAL32)
            answer = b.gcs.recv_match(type="PARAM_VALUE", blocking=True, timeout=2)
            assert answer is not None and answer.param_id == name
            return answer.param_value

        # MAV1_EXTRA1: ATTITUDE's stream group, 10 Hz -> 2 Hz
        assert param_set("MAV1_EXTRA1", 2) == 2
        assert near(b.collect(5.0)["ATTITUDE"], 2, 5.0)

        # WPNAV_SPEED caps the approach to a position target (the mission's cruise speed is 2 m/s)
        assert param_set("WPNAV_SPEED", 50) == 50
        b.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)  # lest the GCS failsafe disarm
        b.guided_and_armed()
        here = b.vehicle.truth()
        b.setpoint(POSITION, x=here.north + 200.0, y=here.east)
        for _ in range(8):  # a ground station beating once a vehicle second
            b.gcs.mav.heartbeat_send(mav.MAV_TYPE_GCS, mav.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            b.wait_vehicle(b.vehicle.t + 1.0)
        assert 0.4 < b.vehicle.truth().speed <= 0.5 + 1e-6  # uncapped it would be near 1.8 m/s by now

        # BATT_CAPACITY: what was used, on twice that capacity, leaves half
        used = b.latest("BATTERY_STATUS").current_consumed
        assert used > 0
        param_set("BATT_CAPACITY", 2 * used)
        report = b.latest("BATTERY_STATUS")  # the vehicle kept drawing meanwhile: judge by this report's own use
        assert report.current_consumed >= used
        assert abs(report.battery_remaining - 100 * (1 - report.current_consumed / (2 * used))) <= 2

        # FS_GCS_TIMEOUT: the ground station falls silent; at 2 s (not the default 5 s) the vehicle disarms
        heard = b.fs.link.gcs_heard
        assert heard is not None and b.fs.armed and param_set("FS_GCS_TIMEOUT", 2.0) == 2.0
        wait_until(lambda: not b.fs.armed, timeout=2, what="the GCS failsafe at FS_GCS_TIMEOUT")
        assert 2.0 < b.vehicle.t - heard < 4.0 and b.fs.stats.failsafes == 1
