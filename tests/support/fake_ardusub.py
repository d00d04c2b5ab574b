"""A scripted ArduSub for bring-up tests: the part of the firmware a step talks to, and a way to make it refuse.

It streams what a ready vehicle streams (HEARTBEAT with its mode and arming, position,
attitude, battery, EKF and GPS), answers SET_MESSAGE_INTERVAL, mode changes, arming and
the mission upload, and follows a vertical set-point — each of which a test can turn into
a refusal or a silence, to see the bring-up step fail with its one line.  Real MAVLink on
loopback; everything it received is kept for the test to check what was commanded.
"""

from __future__ import annotations

import os
import select
import threading
import time
from dataclasses import dataclass

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.geo import LocalFrame  # noqa: E402

M = mavutil.mavlink
EKF_READY = 0x033F  # what ArduSub reports once it uses GPS (attitude, velocities, positions, predictions)


@dataclass
class Behaviour:
    intervals: bool = True  # answer SET_MESSAGE_INTERVAL (else stay silent, as an old firmware would)
    stream: bool = True  # stream telemetry at all
    ekf_flags: int = EKF_READY
    guided: int = M.MAV_RESULT_ACCEPTED
    arm: int = M.MAV_RESULT_ACCEPTED
    mission: int | None = M.MAV_MISSION_ACCEPTED  # None: never answer the upload
    dives: bool = True
    arm_denials: int = 0  # refuse the first arm requests (DENIED), as pre-arm checks do
    denial_switches_to: int | None = None  # ... and change to this mode on each (a pilot, a failsafe)
    failsafe_after_s: float | None = None  # this long after arming a failsafe acts on its own ...
    failsafe_mode: int | None = None  # ... switching to this mode (None: it disarms the vehicle)
    earlier_run_depth_m: float | None = None  # start armed this deep, as a killed run left it ...
    earlier_run_mode: int = 4  # ... in this mode (GUIDED)
    sensor_below_m: float = 0.0  # the depth sensor sits this far under the waterline (ArduSub SITL: 0.36 m)


class FakeArduSub:
    def __init__(self, device: str, mission, behaviour: Behaviour | None = None):
        self.conn = mavutil.mavlink_connection(device, source_system=1, source_component=1, dialect="ardupilotmega")
        self.b = behaviour or Behaviour()
        self.lat, self.lon = LocalFrame(mission.origin_lat, mission.origin_lon).to_latlon(*mission.launch)
        self.mode, self.armed, self.depth, self.vz = 19, False, 0.0, 0.0
        self.received: list = []
        self.arm_modes: list[int] = []  # the mode the vehicle was in at each arm request
        self.armed_at: float | None = None
        self.failsafe_at: int | None = None  # len(received) when the failsafe acted
        if self.b.earlier_run_depth_m is not None:
            self.mode, self.armed, self.depth = self.b.earlier_run_mode, True, self.b.earlier_run_depth_m
            self.armed_at = time.monotonic()
        self._upload = 0
        self._boot = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="fake-ardusub", daemon=True)
        self._thread.start()

    def kinds(self) -> set[str]:
        return {m.get_type() for m in list(self.received)}

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.conn.close()

    # -- the loop ----------------------------------------------------------------------
    def _loop(self) -> None:
        next_beat = next_report = 0.0
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_beat:
                base = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (M.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
                self.conn.mav.heartbeat_send(M.MAV_TYPE_SUBMARINE, M.MAV_AUTOPILOT_ARDUPILOTMEGA, base, self.mode, 4)
                next_beat = now + 0.2
            if (
                self.b.failsafe_after_s is not None
                and self.failsafe_at is None
                and self.armed_at is not None
                and now - self.armed_at >= self.b.failsafe_after_s
            ):
                self.failsafe_at = len(self.received)
                if self.b.failsafe_mode is None:
                    self.armed = False
                else:
                    self.mode = self.b.failsafe_mode
            if now >= next_report and self.b.stream:
                self._report(now)
                next_report = now + 0.05
            if select.select([self.conn.fd], [], [], 0.005)[0]:
                while (msg := self.conn.recv_msg()) is not None:
                    if msg.get_type() != "BAD_DATA":
                        self.received.append(msg)
                        self._handle(msg)

    def _report(self, now: float) -> None:
        ms, m = int((now - self._boot) * 1000), self.conn.mav
        if self.armed and self.mode == 4 and self.b.dives:
            self.depth = max(0.0, self.depth + self.vz * 0.05 * 3)  # a brisk diver keeps the tests short
        elif self.mode == 9:  # SURFACE
            self.depth = max(0.0, self.depth - 0.1)
            if self.armed and self.depth == 0.0:  # ArduSub hands over to ALT_HOLD there (SURFACE_COMPLETE)
                self.mode = 2
        mm = int(-(self.depth + self.b.sensor_below_m) * 1000)
        m.global_position_int_send(ms, round(self.lat * 1e7), round(self.lon * 1e7), mm, mm, 0, 0, 0, 0)
        m.attitude_send(ms, 0.0, 0.0, 0.3, 0.0, 0.0, 0.0)
        m.battery_status_send(0, 0, 0, 2000, [15000] + [65535] * 9, 100, 10, 36, 90)
        m.ekf_status_report_send(self.b.ekf_flags, 0, 0, 0, 0, 0)
        m.gps_raw_int_send(ms * 1000, 3, round(self.lat * 1e7), round(self.lon * 1e7), 0, 100, 100, 0, 0, 10)

    def _handle(self, msg) -> None:
        kind, m = msg.get_type(), self.conn.mav
        if kind == "COMMAND_LONG":
            cmd = int(msg.command)
            if cmd == M.MAV_CMD_SET_MESSAGE_INTERVAL:
                if self.b.intervals:
                    m.command_ack_send(cmd, M.MAV_RESULT_ACCEPTED, 0, 0, 1, 191)
            elif cmd == M.MAV_CMD_DO_SET_MODE:
                result = self.b.guided if int(msg.param2) == 4 else M.MAV_RESULT_ACCEPTED
                if result == M.MAV_RESULT_ACCEPTED:
                    self.mode = int(msg.param2)
                m.command_ack_send(cmd, result, 0, 0, 1, 191)
            elif cmd == M.MAV_CMD_COMPONENT_ARM_DISARM:
                on = msg.param1 > 0.5
                result = self.b.arm if on else M.MAV_RESULT_ACCEPTED
                if on:
                    self.arm_modes.append(self.mode)
                    if len(self.arm_modes) <= self.b.arm_denials:
                        result = M.MAV_RESULT_DENIED
                        self.mode = self.mode if self.b.denial_switches_to is None else self.b.denial_switches_to
                if result == M.MAV_RESULT_ACCEPTED:
                    self.armed = on
                    self.armed_at = time.monotonic() if on else None
                m.command_ack_send(cmd, result, 0, 0, 1, 191)
        elif kind == "MISSION_COUNT" and self.b.mission is not None:
            self._upload = int(msg.count)
            m.mission_request_send(1, 191, 0, 0)
        elif kind == "MISSION_ITEM_INT" and self.b.mission is not None:
            if self.b.mission != M.MAV_MISSION_ACCEPTED or msg.seq + 1 == self._upload:
                m.mission_ack_send(1, 191, self.b.mission, 0)
            else:
                m.mission_request_send(1, 191, msg.seq + 1, 0)
        elif kind == "SET_POSITION_TARGET_LOCAL_NED":
            self.vz = float(msg.vz)
