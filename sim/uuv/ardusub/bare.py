"""The front-seat as a bare ArduSub: what a client meets on a real vehicle, no lock-step, no referee.

``FrontSeat(..., bare=True)`` hands its link to :class:`BareAutopilot`.  The vehicle boots
disarmed in MANUAL on the surface at the mission's launch point, heading for the first
waypoint; vehicle time is wall time since boot times ``speedup`` and every
``time_boot_ms`` is vehicle time.  Physics advances in sub-steps of at most ``SUBSTEP_S``
vehicle seconds, cut at every report, so positions move smoothly between reports.

Streamed with no request, each at its own rate (vehicle time, ArduSub's defaults as
measured on ArduSub SITL 4.7.0-dev, see :mod:`sim.uuv.ardusub.streams`): HEARTBEAT 1 Hz;
ATTITUDE, VFR_HUD 10 Hz; GLOBAL_POSITION_INT, LOCAL_POSITION_NED (only once the position
estimate is ready, relative to the EKF origin = where the vehicle booted), SYSTEM_TIME,
BATTERY_STATUS, EKF_STATUS_REPORT 3 Hz; SYS_STATUS, MISSION_CURRENT, GPS_RAW_INT (3-D fix
only when surfaced) 2 Hz; HOME_POSITION and GPS_GLOBAL_ORIGIN once when the estimate is ready.  No
sonar.  Ground-station requests (commands, modes, parameters, stream rates) are answered
by :mod:`sim.uuv.ardusub.gcs`, as in the lock-step front-seat.  The position estimate is ready
``ekf_ready_s`` after boot (:mod:`sim.uuv.ardusub.ekf`); GUIDED and POSHOLD are refused before.
With ``jitter_s`` or ``drop_reports`` the position and attitude reports go out off their
cadence and some never do, as over a radio link (:mod:`sim.uuv.ardusub.jitter`, seeded).

Modes: GUIDED flies set-points (:mod:`sim.uuv.ardusub.guided`); AUTO flies the uploaded mission
(:mod:`sim.uuv.ardusub.auto`); SURFACE rises to the surface, where it switches itself to ALT_HOLD as
ArduSub does; STABILIZE, ALT_HOLD, POSHOLD and
CIRCLE keep depth with no horizontal drive (no pilot here); MANUAL and ACRO and a disarmed vehicle apply no thrust — the
vehicle keeps its depth (neutral buoyancy) and drifts with the current.  The vehicle never
disarms itself except by ArduSub's GCS failsafe (FS_GCS_ENABLE 2, FS_GCS_TIMEOUT 5 s, the
parameters read each time, :mod:`sim.uuv.ardusub.params`): once a heartbeat from MAV_GCS_SYSID (255)
has been heard, FS_GCS_TIMEOUT vehicle seconds without one disarm it.  Position targets are
approached at WPNAV_SPEED at most; the battery's remaining percent counts against
BATT_CAPACITY.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.auto import AutoMission  # noqa: E402
from sim.uuv.ardusub.depth import SURFACE_VZ, Depth  # noqa: E402
from sim.uuv.ardusub.ekf import EkfReadiness  # noqa: E402
from sim.uuv.ardusub.gcs import heartbeat_send, sensor_bits  # noqa: E402
from sim.uuv.ardusub.guided import Target, from_global_int, from_local_ned  # noqa: E402
from sim.uuv.ardusub.host import Host  # noqa: E402
from sim.uuv.ardusub.jitter import JitteredSchedule  # noqa: E402
from sim.uuv.ardusub.streams import StreamSchedule  # noqa: E402
from sim.uuv.interface import energy_consumed_hj  # noqa: E402

__all__ = ["BareAutopilot", "Truth", "SUBSTEP_S"]

mav = mavutil.mavlink

#: Longest physics sub-step (vehicle seconds).
SUBSTEP_S = 0.1
#: Longest wait for input (wall seconds) when nothing is due: commands are answered within it anyway.
IDLE_S = 0.05
AUTO, GUIDED, SURFACE, MANUAL, ACRO, ALT_HOLD = 3, 4, 9, 19, 1, 2
#: Volts the battery's mAh are counted at (a 4-cell pack).
PACK_V = 14.8


@dataclass(frozen=True)
class Truth:
    """The vehicle's true state for tests: ``x, y`` in the mission frame (east, north),
    ``north, east`` from where it booted, depth (m, + down), heading (compass rad), speed
    through water (m/s) and vehicle time ``t`` (s)."""

    t: float
    x: float
    y: float
    north: float
    east: float
    depth: float
    heading: float
    speed: float


class BareAutopilot:
    """A front-seat's (its :class:`~sim.uuv.ardusub.host.Host`'s) vehicle run as ArduSub runs it (see module docstring)."""

    def __init__(self, fs: Host, ekf_ready_s: float, jitter_s: float = 0.0, drop_reports: float = 0.0, seed: int = 0):
        self.fs, self.conn, self.world = fs, fs.conn, fs.world
        self.spec = fs.mission.vehicle
        self.ekf = EkfReadiness(float(ekf_ready_s))
        s = self.world.state
        self.x0, self.y0 = float(s.x[0]), float(s.y[0])  # the EKF origin and home
        self.t = 0.0
        self.depth = Depth()
        self.target = Target.hold(0.0, 0.0)
        # a vehicle behind a radio link: position and attitude reports off their cadence, some lost (seeded)
        self.streams: StreamSchedule | JitteredSchedule = fs.streams
        if jitter_s or drop_reports:
            self.streams = JitteredSchedule(fs.streams, jitter_s, drop_reports, seed)
        self.auto = AutoMission(fs.missions, self._north_east)
        self.vn = self.ve = 0.0  # ground velocity over the last sub-step
        self._origin_sent = False
        self._sent_at: dict[int, float] = {}  # GLOBAL_POSITION_INT time_boot_ms -> wall time sent
        self._boot = time.monotonic()

    # -- clock and physics -------------------------------------------------------------
    def now(self) -> float:
        """Vehicle seconds since boot."""
        return (time.monotonic() - self._boot) * self.fs.speedup

    def truth(self) -> Truth:
        s = self.world.state
        x, y = float(s.x[0]), float(s.y[0])
        return Truth(self.t, x, y, y - self.y0, x - self.x0, self.depth.depth, float(s.heading[0]), float(s.surge[0]))

    def serve(self, duration_s: float | None = None) -> None:
        deadline = None if duration_s is None else time.monotonic() + duration_s
        while not self.fs.stop_requested() and (deadline is None or time.monotonic() < deadline):
            now = self.now()
            while True:
                event = min(self.t + SUBSTEP_S, self.streams.next_time())
                if event > now:
                    break
                if event > self.t:
                    self._substep(event - self.t)
                for name in self.streams.due(self.t):
                    self._send(name)
            self._housekeeping()
            self.fs.missions.update()
            wait = (min(self.t + SUBSTEP_S, self.streams.next_time()) - self.now()) / self.fs.speedup
            msg = self.conn.recv_match(blocking=True, timeout=min(max(wait, 0.0005), IDLE_S))
            while msg is not None:  # answer everything that is waiting
                self.fs.handle(msg)
                msg = self.conn.recv_match(blocking=False)

    def _housekeeping(self) -> None:
        if self.ekf.ready(self.t) and not self._origin_sent:
            self._origin_sent = True
            self._status(mav.MAV_SEVERITY_INFO, "EKF3 IMU0 is using GPS")
            self._send("GPS_GLOBAL_ORIGIN")
            self._send("HOME_POSITION")
        heard, timeout = self.fs.link.gcs_heard, self.fs.params.gcs_failsafe_s()
        if timeout is not None and heard is not None and self.fs.armed and self.t - heard > timeout:
            self._status(mav.MAV_SEVERITY_CRITICAL, f"MYGCS: {int(self.fs.params['MAV_GCS_SYSID'])}, heartbeat lost")
            self._status(mav.MAV_SEVERITY_INFO, "Disarming motors")
            self.set_armed(False)
            self.fs.stats.failsafes += 1

    def _here(self) -> tuple[float, float]:
        s = self.world.state
        return float(s.y[0]) - self.y0, float(s.x[0]) - self.x0

    def _substep(self, dt: float) -> None:
        fs, s = self.fs, self.world.state
        heading, speed, vz = float(s.heading[0]), 0.0, 0.0
        if fs.mode == AUTO:
            self.auto.begin()
        if fs.armed and fs.mode in (GUIDED, AUTO):
            if fs.mode == AUTO:
                north, east = self._here()
                self.target = self.auto.target(self.t, north, east, self.depth.depth)
            if self.target.expired(self.t):
                self.target = self.target.timed_out(self.depth.depth)
            self.target = self.target.advanced(dt)
            north, east = self._here()
            heading, speed, want = self.target.command(north, east, heading, self.fs.params.wpnav_speed_ms())
            if want is None:
                assert self.target.depth is not None
                want = self.depth.toward(self.target.depth, dt)
            vz = want
        elif fs.armed and fs.mode == SURFACE:
            if self.depth.surfaced:  # ArduSub's SURFACE hands over to ALT_HOLD at the surface (mode_surface.cpp)
                self.enter_mode(ALT_HOLD)
            else:
                vz = -SURFACE_VZ
        x, y = float(s.x[0]), float(s.y[0])
        self.depth.step(vz, dt)
        one = np.ones(1, dtype=bool)
        surfaced = np.array([self.depth.surfaced])  # depth is this front-seat's own state (ascent included)
        self.world.advance(self.t, np.array([heading]), np.array([speed]), surfaced, one, dt=dt, vertical=False)
        self.t += dt
        self.vn, self.ve = (float(s.y[0]) - y) / dt, (float(s.x[0]) - x) / dt
        fs.stats.ticks += 1

    # -- MAVLink out -------------------------------------------------------------------
    def _status(self, severity: int, text: str) -> None:
        self.fs.send_status(severity, text)

    def _estimate(self) -> tuple[float, float]:
        """Where the vehicle believes it is (mission frame east, north)."""
        s, w = self.world.state, self.world
        if w.noise is None:
            return float(s.x[0]), float(s.y[0])
        ex, ey = w.nav.estimate(s.x, s.y)
        return float(ex[0]), float(ey[0])

    def _battery(self) -> tuple[int, int, int]:
        """(energy used in hJ, percent left, volts in mV) of the vehicle's own pack, full at boot.

        The scenario's starting charge is virtual (the range's fuel gauge counts it); the
        pack in a real vehicle is whatever the range charged, here a full one of
        BATT_CAPACITY mAh.
        """
        w = self.world
        hj = float(energy_consumed_hj(w.start_wh, w.state.energy_wh)[0])
        capacity = self.fs.params["BATT_CAPACITY"]
        frac = 1.0 - self.consumed_mah(hj) / capacity if capacity > 0 else 0.0
        return int(hj), int(np.clip(round(frac * 100), 0, 100)), int(14800 * (0.85 + 0.15 * min(max(frac, 0), 1)))

    @staticmethod
    def consumed_mah(hj: float) -> float:
        return hj * 100 / 3600 / PACK_V * 1000

    def _send(self, name: str) -> None:
        m, ms = self.conn.mav, int(self.t * 1000)
        s = self.world.state
        heading = float(s.heading[0])
        yaw = math.atan2(math.sin(heading), math.cos(heading))
        hdg = int(round(math.degrees(heading) % 360 * 100)) % 36000
        depth, vz = self.depth.depth, self.depth.vz
        ready, gps = self.ekf.ready(self.t), self.ekf.gps_found(self.t)
        if name == "HEARTBEAT":
            heartbeat_send(self.conn, self.fs.mode, self.fs.armed)
        elif name == "ATTITUDE":
            m.attitude_send(ms, 0.0, 0.0, yaw, 0.0, 0.0, float(s.yaw_rate[0]))
        elif name == "VFR_HUD":
            throttle = int(round(100 * float(s.surge[0]) / self.spec.max_speed)) if self.fs.armed else 0
            m.vfr_hud_send(0.0, math.hypot(self.vn, self.ve), hdg // 100, throttle, -depth, -vz)
        elif name == "GLOBAL_POSITION_INT":
            lat = lon = 0
            if gps:
                la, lo = self.fs.frame.to_latlon(*self._estimate())
                lat, lon = int(round(la * 1e7)), int(round(lo * 1e7))
            mm = int(round(-depth * 1000))
            self._sent_at.setdefault(ms, time.perf_counter())
            m.global_position_int_send(
                ms, lat, lon, mm, mm, int(self.vn * 100), int(self.ve * 100), int(vz * 100), hdg if gps else 0
            )
        elif name == "LOCAL_POSITION_NED":
            if ready:  # ArduSub sends none before its EKF has a horizontal position
                ex, ey = self._estimate()
                m.local_position_ned_send(ms, ey - self.y0, ex - self.x0, depth, self.vn, self.ve, vz)
        elif name == "GPS_RAW_INT":
            fix = (mav.GPS_FIX_TYPE_3D_FIX if self.depth.surfaced else mav.GPS_FIX_TYPE_NO_FIX) if gps else 0
            lat = lon = 0
            if fix == mav.GPS_FIX_TYPE_3D_FIX:
                la, lo = self.fs.frame.to_latlon(float(s.x[0]), float(s.y[0]))
                lat, lon = int(round(la * 1e7)), int(round(lo * 1e7))
            ground = math.hypot(self.vn, self.ve)
            cog = int(round(math.degrees(math.atan2(self.ve, self.vn)) % 360 * 100)) % 36000
            m.gps_raw_int_send(
                ms * 1000, fix, lat, lon, 0, 121 if fix == 3 else 65535, 200 if fix == 3 else 65535,
                int(ground * 100), cog, 10 if fix == 3 else 0,
            )  # fmt: skip
        elif name == "SYS_STATUS":
            _, percent, mv = self._battery()
            m.sys_status_send(*sensor_bits(self.fs.mode, gps), 0, mv, -1, percent, 0, 0, 0, 0, 0, 0)
        elif name == "BATTERY_STATUS":
            hj, percent, mv = self._battery()
            mah = int(self.consumed_mah(hj))
            m.battery_status_send(
                0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LION, 32767, [mv] + [65535] * 9, -1, mah, hj,
                percent,
            )  # fmt: skip
        elif name == "EKF_STATUS_REPORT":
            var = 0.01 if ready else 0.0
            m.ekf_status_report_send(self.ekf.flags(self.t), var, var, var, 0.0, 0.0)
        elif name == "MISSION_CURRENT":
            self.fs.missions.send_current()
        elif name == "SYSTEM_TIME":
            m.system_time_send(int(time.time() * 1e6), ms)
        elif name in ("GPS_GLOBAL_ORIGIN", "HOME_POSITION"):
            la, lo = self.fs.frame.to_latlon(self.x0, self.y0)
            lat, lon = int(round(la * 1e7)), int(round(lo * 1e7))
            if name == "GPS_GLOBAL_ORIGIN":
                m.gps_global_origin_send(lat, lon, 0, ms * 1000)
            else:
                m.home_position_send(lat, lon, 0, 0.0, 0.0, 0.0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, ms * 1000)

    # -- MAVLink in (ground-station requests are sim.uuv.ardusub.gcs's) ------------------------
    def setpoint(self, msg) -> None:
        """SET_POSITION_TARGET_LOCAL_NED / _GLOBAL_INT, read as ArduSub reads them (sim.uuv.ardusub.guided)."""
        if msg.get_type() == "SET_POSITION_TARGET_LOCAL_NED":
            self._round_trip(int(msg.time_boot_ms))
            north, east = self._here()
            heading = float(self.world.state.heading[0])
            self._accept(from_local_ned(msg, north, east, self.depth.depth, heading, self.t))
        else:
            self._accept(from_global_int(msg, self._north_east, self.t))

    def _round_trip(self, stamp: int) -> None:
        """Time from the position report stamped ``stamp`` leaving to the first set-point that answers it."""
        sent = self._sent_at.get(stamp)
        if sent is not None and stamp not in self.fs.stats.latency_s:
            self.fs.stats.latency_s[stamp] = time.perf_counter() - sent
        if len(self._sent_at) > 4096:  # keep the last minutes' reports only
            for old in list(self._sent_at)[:2048]:
                del self._sent_at[old]

    def _north_east(self, lat: float, lon: float) -> tuple[float, float]:
        x, y = self.fs.frame.to_local(lat, lon)
        return y - self.y0, x - self.x0

    def _accept(self, target: Target | None) -> None:
        if target is None or self.fs.mode != GUIDED:
            self.fs.stats.ignored += 1  # ArduSub drops these silently
            return
        self.target = target
        self.fs.stats.setpoints += 1

    # -- what sim.uuv.ardusub.gcs asks of the vehicle ----------------------------------------------
    def vehicle_time(self) -> float:
        return self.t

    def mode_refusal(self, mode: int) -> str | None:
        if self.ekf.mode_allowed(mode, self.t):
            return None
        return f"Mode change failed: {mavutil.mode_mapping_sub[mode]} requires position"

    def enter_mode(self, mode: int) -> None:
        changed = mode != self.fs.mode
        if changed:
            self.target = Target.hold(self.depth.depth, self.t)  # GUIDED starts by holding where it is
        self.fs.mode = mode
        if changed and mode == AUTO:
            self.auto.start()  # ArduSub: entering the mode it is in already changes nothing

    def arm_refusal(self, on: bool) -> str | None:
        return None  # ARMING_CHECK 448: ArduSub arms in any mode, before the EKF is ready

    def set_armed(self, on: bool) -> None:
        self.fs.armed = on
        self.target = Target.hold(self.depth.depth, self.t)

    def send_on_request(self, name: str) -> bool:
        if name in ("HOME_POSITION", "GPS_GLOBAL_ORIGIN") and not self.ekf.ready(self.t):
            return False
        self._send(name)
        return True
