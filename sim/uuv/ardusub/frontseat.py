"""A simulated front-seat autopilot that speaks MAVLink 2, ArduSub style.

It flies one scenario's vehicle (:class:`sim.uuv.world.World` with N = 1) behind a pymavlink
endpoint, so the back-seat autonomy, a ground station or the bridge talk to it exactly
as to a vehicle: HEARTBEAT (MAV_TYPE_SUBMARINE), SYS_STATUS, BATTERY_STATUS,
LOCAL_POSITION_NED, GLOBAL_POSITION_INT, ATTITUDE, GPS_RAW_INT (a fix only on the
surface), OBSTACLE_DISTANCE (a 360-beam sonar scan, five messages) and OBSTACLE_DISTANCE_3D
(one closest point per contact), SYSTEM_TIME; GUIDED velocity+yaw set-points
(SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT, type mask 2503); and the mission protocol with
MISSION_CURRENT (:mod:`sim.uuv.ardusub.mission_server`).  Both flavours answer every ground-station request
(commands, modes, parameters, stream rates, FTP) the same, ArduSub way (:mod:`sim.uuv.ardusub.gcs`,
:mod:`sim.uuv.ardusub.params`); in lock-step a requested stream rate is acknowledged and read back, but
telemetry still goes out once per step (the lock-step's contract with the back-seat), plus
EKF_STATUS_REPORT.

Clock: with ``lockstep`` the simulated time advances one step when the set-point for the
current step arrives (its ``time_boot_ms`` names the step), so a one-hour mission flies as
fast as the back-seat can answer; otherwise it runs in real time times ``speedup`` with
the latest set-point.  SYSTEM_TIME closes every step's telemetry.  Failsafe: no set-point
for ``failsafe_s`` wall seconds (lock-step) or simulated seconds (real time) -> hold
position and surface, as an autopilot would.  A referee scorer ends the run (recovered,
collision, out of the area, battery empty, time limit) and the vehicle disarms.

With ``bare`` it is none of that but a bare ArduSub (:mod:`sim.uuv.ardusub.bare`): real time times
``speedup``, each message streamed at ArduSub's own rate, a position estimate that is
ready only ``ekf_ready_s`` after boot, GUIDED set-points as ArduSub reads them, depth as
a state, no sonar and no referee; ``report_jitter_s`` and ``drop_reports`` (seeded by ``seed``)
disturb its position and attitude reports as a radio link would (:mod:`sim.uuv.ardusub.jitter`).
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from rapt.errors import InputError  # noqa: E402
from sim.uuv.ardusub.bare import PACK_V, BareAutopilot  # noqa: E402
from sim.uuv.ardusub.ekf import FLAGS_READY  # noqa: E402
from sim.uuv.ardusub.gcs import GroundStationLink, heartbeat_send, sensor_bits  # noqa: E402
from sim.uuv.ardusub.host import FrontSeatStats  # noqa: E402
from sim.uuv.ardusub.jitter import check_report_timing  # noqa: E402
from sim.uuv.ardusub.mission_server import MissionServer  # noqa: E402
from sim.uuv.ardusub.params import ParameterTable  # noqa: E402
from sim.uuv.ardusub.streams import StreamSchedule  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.interface import DEPTH_M, decode_command  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.scenario import make_scenarios  # noqa: E402
from sim.uuv.scoring import Scorer  # noqa: E402
from sim.uuv.sonar import BEAMS_PER_MESSAGE, SCAN_BEAMS  # noqa: E402
from sim.uuv.world import Telemetry, World, scenario_generators  # noqa: E402

__all__ = ["FrontSeat", "GUIDED", "MANUAL", "SURFACE", "VELOCITY_YAW_MASK"]

mav = mavutil.mavlink
GUIDED, MANUAL, SURFACE = 4, 19, 9
#: Velocity and yaw used; position, acceleration and yaw rate ignored.
VELOCITY_YAW_MASK = 2503
#: ArduSub zeroes a velocity target not refreshed within this many seconds.
SETPOINT_TIMEOUT_S = 3.0


@dataclass
class _Setpoint:
    heading: float = 0.0
    speed: float = 0.0
    surface: bool = False
    tick_ms: int = -1
    received: float = -1e9  # simulated time


class FrontSeat:
    """One simulated vehicle behind a MAVLink endpoint (see module docstring)."""

    def __init__(
        self,
        mission: Mission,
        u,
        connection: str,
        *,
        lockstep: bool = True,
        speedup: float = 1.0,
        stochastic: bool = False,
        seed: int = 0,
        failsafe_s: float = 5.0,
        sysid: int = 1,
        telemetry_period_s: float = 0.5,
        bias=None,
        bare: bool = False,
        ekf_ready_s: float = 5.0,
        gcs_failsafe_s: float | None = 5.0,
        report_jitter_s: float = 0.0,
        drop_reports: float = 0.0,
    ):
        self.mission = mission
        self.u = np.asarray(u, dtype=float).reshape(1, -1)
        scen = make_scenarios(mission, self.u)
        if not scen.valid[0]:
            raise InputError(f"scenario: invalid for mission '{mission.name}' ({scen.invalid_reason[0]})")
        if not speedup > 0:
            raise InputError(f"speedup: expected a factor > 0, got {speedup}")
        if not ekf_ready_s >= 0:
            raise InputError(f"ekf_ready_s: expected vehicle seconds >= 0, got {ekf_ready_s}")
        check_report_timing(report_jitter_s, drop_reports)
        if (report_jitter_s or drop_reports) and not bare:
            raise InputError(
                "report_jitter_s: report jitter and drops are the bare front-seat's (lock-step closes each step "
                "itself); fly bare"
            )
        self.scen = scen
        # a biased vehicle (sim.uuv.bias) flies like a real one whose speed, tide, compass or
        # battery differ from the model; the back-seat on the far side does not know
        self.bias = bias
        rngs = scenario_generators(self.u, seed) if stochastic else None
        self.world = World(scen, rngs, bias, 0 if bare else SCAN_BEAMS)
        self.referee = Scorer(scen)
        self.frame = LocalFrame(mission.origin_lat, mission.origin_lon)
        self.lockstep, self.speedup, self.failsafe_s = lockstep and not bare, float(speedup), float(failsafe_s)
        self.telemetry_period_s = telemetry_period_s
        self.conn = mavutil.mavlink_connection(
            connection, source_system=sysid, source_component=1, dialect="ardupilotmega"
        )
        self.armed = False
        self.mode = MANUAL
        self.k = 0
        self.setpoint = _Setpoint()
        self.stats = FrontSeatStats()
        self._stop = threading.Event()
        self._boot = time.time()
        self.tel: Telemetry = self.world.telemetry(0.0)
        self.params = ParameterTable(self._mission_parameters(sysid, gcs_failsafe_s))
        self.streams = StreamSchedule(params=self.params)
        self.bare: BareAutopilot | None = None
        home = self.frame.to_latlon(float(self.world.state.x[0]), float(self.world.state.y[0]))
        self.missions = MissionServer(self.conn, (*home, 0.0), self.send_status, self._mission_clock)
        if bare:  # a real vehicle knows no referee
            self.bare = BareAutopilot(self, ekf_ready_s, report_jitter_s, drop_reports, seed)
        else:
            self._referee()  # the first report counts, as in a batch
        self.link = GroundStationLink(self, self.bare if self.bare is not None else self, self.params, self.streams)

    def _mission_parameters(self, sysid: int, gcs_failsafe_s: float | None) -> dict[str, float]:
        """ArduSub's parameters this vehicle sets from its mission (sim.uuv.ardusub.params)."""
        spec = self.mission.vehicle
        return {
            "MAV_SYSID": sysid,
            "FS_GCS_ENABLE": 0 if gcs_failsafe_s is None else 2,
            "FS_GCS_TIMEOUT": 5.0 if gcs_failsafe_s is None else gcs_failsafe_s,
            "WPNAV_SPEED": spec.cruise_speed * 100,
            "BATT_CAPACITY": round(spec.battery_wh / PACK_V * 1000),
        }

    # -- public ----------------------------------------------------------------------
    @property
    def t(self) -> float:
        return self.k * self.mission.dt

    def _mission_clock(self) -> float:
        """Vehicle seconds for the mission protocol's timeouts (wall seconds in lock-step)."""
        return self.bare.now() if self.bare is not None else time.monotonic()

    @property
    def mission_items(self) -> list:
        """The mission's items as they were uploaded (MISSION_ITEM_INT or MISSION_ITEM messages)."""
        return [it.message for it in self.missions.lists[0] if it.message is not None]

    @property
    def ended(self) -> bool:
        return bool(self.stats.ended)

    def stop(self) -> None:
        self._stop.set()

    def stop_requested(self) -> bool:
        return self._stop.is_set()

    def close(self) -> None:
        self._stop.set()
        self.conn.close()

    def serve(self, duration_s: float | None = None) -> None:
        """Run until :meth:`stop` (or ``duration_s`` wall seconds)."""
        if self.bare is not None:
            self.bare.serve(duration_s)
            return
        deadline = None if duration_s is None else time.monotonic() + duration_s
        last_hb = last_tel = 0.0
        last_tick = time.monotonic()
        waiting_since = time.monotonic()
        while not self._stop.is_set() and (deadline is None or time.monotonic() < deadline):
            now = time.monotonic()
            if now - last_hb >= 1.0:
                self._heartbeat()
                self.missions.send_current()
                last_hb = now
            msg = self.conn.recv_match(blocking=True, timeout=0.02)
            if msg is not None:
                self.handle(msg)
            self.missions.update()
            flying = self.armed and self.mode == GUIDED and not self.ended
            if self.lockstep:
                if not flying:
                    waiting_since = time.monotonic()  # the failsafe counts from when flying begins
                if flying and self.setpoint.tick_ms == self._tick_ms():
                    self._step(self.setpoint)
                    waiting_since = time.monotonic()
                elif flying and time.monotonic() - waiting_since > self.failsafe_s:
                    self._failsafe()
                    waiting_since = time.monotonic()
                elif time.monotonic() - last_tel >= self.telemetry_period_s:
                    self._send_telemetry()  # repeat the current step for late joiners
                    last_tel = time.monotonic()
            else:
                period = self.mission.dt / self.speedup
                if time.monotonic() - last_tick >= period:
                    last_tick += period
                    if flying:
                        sp = self.setpoint
                        if self.t - sp.received > self.failsafe_s:
                            self._failsafe()
                        else:
                            if self.t - sp.received > SETPOINT_TIMEOUT_S:
                                sp = _Setpoint(heading=sp.heading, surface=sp.surface)
                            self._step(sp)
                    else:
                        self._send_telemetry()

    # -- the vehicle -----------------------------------------------------------------
    def _tick_ms(self) -> int:
        return int(round(self.t * 1000))

    def _step(self, sp: _Setpoint) -> None:
        moving = np.ones(1, dtype=bool)
        self.world.advance(self.t, np.array([sp.heading]), np.array([sp.speed]), np.array([sp.surface]), moving)
        self.k += 1
        self.stats.ticks += 1
        self.tel = self.world.telemetry(self.t)
        self._referee()
        self._send_telemetry()

    def _failsafe(self) -> None:
        self.stats.failsafes += 1
        self.send_status(mav.MAV_SEVERITY_WARNING, "failsafe: no back-seat set-point, holding on the surface")
        self._step(
            _Setpoint(
                heading=float(self.tel.heading[0]), speed=0.0, surface=True, tick_ms=self._tick_ms(), received=self.t
            )
        )

    def _referee(self) -> None:
        ended = self.referee.update_from(self.tel, np.ones(1, dtype=bool))[0]
        reason = ""
        if ended:
            reason = self.referee.end_reason()
        elif self.t >= self.mission.time_limit_s:
            reason = "time limit"
        if reason:
            self.stats.ended, self.stats.ticks_at_end = reason, self.k
            self.armed = False
            self.send_status(mav.MAV_SEVERITY_NOTICE, f"run ended: {reason}")

    # -- MAVLink out -----------------------------------------------------------------
    def _heartbeat(self) -> None:
        heartbeat_send(self.conn, self.mode, self.armed)

    def send_status(self, severity: int, text: str) -> None:
        """Send a STATUSTEXT (cut to 50 characters) and keep it in ``stats.log``."""
        self.stats.log.append(text)
        self.conn.mav.statustext_send(severity, text[:50].encode())

    def _send_telemetry(self) -> None:
        tel, ms, m = self.tel, self._tick_ms(), self.conn.mav
        east, north = float(tel.est_x[0]), float(tel.est_y[0])
        depth = 0.0 if tel.surfaced[0] else DEPTH_M
        s = self.world.state
        ve = float(s.surge[0] * np.sin(s.heading[0]))
        vn = float(s.surge[0] * np.cos(s.heading[0]))
        m.attitude_send(ms, 0.0, 0.0, float(tel.heading[0]), 0.0, 0.0, float(s.yaw_rate[0]))
        m.local_position_ned_send(ms, north, east, depth, vn, ve, 0.0)
        lat, lon = self.frame.to_latlon(east, north)
        hdg = int(round(np.degrees(tel.heading[0]) % 360 * 100)) % 36000
        m.global_position_int_send(
            ms,
            int(round(lat * 1e7)),
            int(round(lon * 1e7)),
            int(-depth * 1000),
            int(-depth * 1000),
            int(vn * 100),
            int(ve * 100),
            0,
            hdg,
        )
        percent = int(np.clip(round(tel.battery[0] * 100), 0, 100))
        volts = [int(14800 * (0.85 + 0.15 * tel.battery[0]))] + [65535] * 9
        m.battery_status_send(
            0,
            mav.MAV_BATTERY_FUNCTION_ALL,
            mav.MAV_BATTERY_TYPE_LION,
            2000,
            volts,
            -1,
            int(tel.energy_hj[0] * 100 / 3600 / 14.8 * 1000),
            int(tel.energy_hj[0]),
            percent,
        )
        m.sys_status_send(*sensor_bits(self.mode, True), 0, volts[0], -1, percent, 0, 0, 0, 0, 0, 0)
        m.ekf_status_report_send(FLAGS_READY, 0.01, 0.01, 0.01, 0.0, 0.0)  # its position is known from the start
        fix = 3 if tel.surfaced[0] else 0
        m.gps_raw_int_send(
            ms * 1000,
            fix,
            int(round(lat * 1e7)) if fix else 0,
            int(round(lon * 1e7)) if fix else 0,
            0,
            65535,
            65535,
            65535,
            65535,
            12 if fix else 0,
        )
        self._send_sonar(ms)
        m.system_time_send(int(time.time() * 1e6), ms)  # closes this step's telemetry

    def _send_sonar(self, ms: int) -> None:
        """Each contact's closest point (OBSTACLE_DISTANCE_3D, LOCAL_NED, what the expert reads)
        and the 360-beam scan in five OBSTACLE_DISTANCE messages (BODY_FRD, 1 degree apart,
        ``angle_offset`` 0, 72, ... 288; uint16 cm, max + 1 where nothing is seen)."""
        tel, m = self.tel, self.conn.mav
        rng = self.mission.vehicle.sonar_range_m
        for j in np.flatnonzero(tel.detected[0]):
            cx, cy = float(tel.contact_x[0, j]), float(tel.contact_y[0, j])
            m.obstacle_distance_3d_send(
                ms, mav.MAV_DISTANCE_SENSOR_ULTRASOUND, mav.MAV_FRAME_LOCAL_NED, int(j), cy, cx, 0.0, 0.0, rng
            )
        assert tel.scan is not None, "the front-seat's world scans (SCAN_BEAMS > 0)"
        cm = np.round(tel.scan[0] * 100.0).astype(np.int64)
        for start in range(0, SCAN_BEAMS, BEAMS_PER_MESSAGE):
            m.obstacle_distance_send(
                ms * 1000,
                mav.MAV_DISTANCE_SENSOR_ULTRASOUND,
                cm[start : start + BEAMS_PER_MESSAGE].tolist(),
                0,
                0,
                int(rng * 100),
                1.0,
                float(start),
                mav.MAV_FRAME_BODY_FRD,
            )

    # -- MAVLink in ------------------------------------------------------------------
    def handle(self, msg) -> None:
        """Answer one incoming MAVLink message."""
        kind = msg.get_type()
        if kind == "BAD_DATA" or self.missions.handle(msg) or self.link.handle(msg):
            return  # the mission protocol (sim.uuv.ardusub.mission_server), then the rest of a ground station's requests
        if kind in ("SET_POSITION_TARGET_LOCAL_NED", "SET_POSITION_TARGET_GLOBAL_INT"):
            if self.bare is not None:
                self.bare.setpoint(msg)
            else:
                self._setpoint(msg, kind)

    # -- what sim.uuv.ardusub.gcs asks of the lock-step vehicle ---------------------------------
    def vehicle_time(self) -> float:
        return self.t

    def mode_refusal(self, mode: int) -> str | None:
        return None  # its position is known from the start

    def enter_mode(self, mode: int) -> None:
        self.mode = mode

    def arm_refusal(self, on: bool) -> str | None:
        return "Arm: the run has ended" if on and self.ended else None

    def set_armed(self, on: bool) -> None:
        self.armed = on

    def send_on_request(self, name: str) -> bool:
        if name in ("HOME_POSITION", "GPS_GLOBAL_ORIGIN"):
            lat, lon = self.frame.to_latlon(float(self.world.state.x[0]), float(self.world.state.y[0]))
            lat7, lon7, usec = int(round(lat * 1e7)), int(round(lon * 1e7)), self._tick_ms() * 1000
            if name == "GPS_GLOBAL_ORIGIN":
                self.conn.mav.gps_global_origin_send(lat7, lon7, 0, usec)
            else:
                self.conn.mav.home_position_send(lat7, lon7, 0, 0.0, 0.0, 0.0, [1.0, 0, 0, 0], 0.0, 0.0, 0.0, usec)
        else:
            self._send_telemetry()  # the step's telemetry carries every streamed message
        return True

    def _setpoint(self, msg, kind: str) -> None:
        frames = (
            (mav.MAV_FRAME_LOCAL_NED,)
            if kind.endswith("LOCAL_NED")
            else (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
        )
        if self.mode != GUIDED or msg.coordinate_frame not in frames or msg.type_mask != VELOCITY_YAW_MASK:
            self.stats.ignored += 1  # ArduSub drops such set-points silently
            return
        heading, speed, surface = decode_command(msg.vx, msg.vy, msg.vz, msg.yaw)
        self.setpoint = _Setpoint(float(heading), float(speed), bool(surface), int(msg.time_boot_ms), self.t)
        self.stats.setpoints += 1
