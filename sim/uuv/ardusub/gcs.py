"""What ArduSub answers a ground station, shared by both front-seat flavours.

Every request a ground station (QGroundControl, MAVProxy, MAVSDK, pymavlink) sends on
connect and in use gets the answer ArduSub SITL 4.7.0-dev gives (recorded in
``tests/sim/uuv/ardusub/ardusub_answers.json``, compared by ``tests/sim/uuv/ardusub/conformance.py``):

- HEARTBEAT: type SUBMARINE, autopilot ARDUPILOTMEGA, base_mode STABILIZE | MANUAL_INPUT |
  CUSTOM_MODE (+ GUIDED in AUTO, GUIDED, CIRCLE, POSHOLD, + SAFETY_ARMED), system_status
  STANDBY or ACTIVE when armed.  SYS_STATUS carries SITL's sensor bits (:func:`sensor_bits`:
  the fence is present and healthy but not enabled, so no ground station reports a breach).
- COMMAND_LONG: ARM_DISARM (ACK, then on arming GPS_GLOBAL_ORIGIN and HOME_POSITION once
  the position is known, then "Arming motors" / "Disarming motors"); DO_SET_MODE (an
  unknown mode: FAILED + "No such mode N"; a position mode before the EKF has a position:
  FAILED + "Mode change failed: GUIDED requires position"; no CUSTOM_MODE flag: DENIED);
  REQUEST_MESSAGE and REQUEST_AUTOPILOT_CAPABILITIES (ACK, then the message; HOME_POSITION
  before the EKF has a position: ACCEPTED and nothing sent);
  SET/GET_MESSAGE_INTERVAL (GET: MESSAGE_INTERVAL, then the ACK); anything else UNSUPPORTED.
- SET_MODE: as DO_SET_MODE but never acknowledged (this firmware sends no COMMAND_ACK).
- PARAM_REQUEST_LIST (a three-line banner, then every PARAM_VALUE with index and count),
  PARAM_REQUEST_READ (by index, or by name with index -1; unknown: no answer) and
  PARAM_SET (PARAM_VALUE with the stored value; unknown, NaN: no answer), see
  :mod:`sim.uuv.ardusub.params`.
- REQUEST_DATA_STREAM: no answer; the group's MAV1_* rate changes.
- MAVLink FTP: ``@PARAM/param.pck``, the parameter file MAVProxy and QGroundControl fetch
  first (:mod:`sim.uuv.ardusub.ftp`), then the banner; any other file gets NAK FileNotFound.

The vehicle behind it (lock-step :class:`sim.uuv.ardusub.frontseat.FrontSeat` or the bare
:class:`sim.uuv.ardusub.bare.BareAutopilot`) supplies the few things that differ: its clock, whether
a mode or arming is refused, and the messages it can send on request.
"""

from __future__ import annotations

import os
from typing import Protocol

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from sim.uuv.ardusub.ftp import OPEN_RO, ParamFileServer  # noqa: E402
from sim.uuv.ardusub.params import FIRMWARE, ParameterTable  # noqa: E402
from sim.uuv.ardusub.streams import StreamSchedule  # noqa: E402

__all__ = [
    "CAPABILITIES",
    "GroundStationLink",
    "MODES",
    "sensor_bits",
    "SW_VERSION",
    "Vehicle",
    "heartbeat_send",
]

mav = mavutil.mavlink

#: The modes ArduSub has (ArduSub/mode.h); any other gets FAILED and "No such mode N".
MODES = frozenset(mavutil.mode_mapping_sub)
#: Modes that fly under position control (GUIDED_ENABLED in the heartbeat): AUTO, GUIDED, CIRCLE, POSHOLD.
GUIDED_MODES = frozenset({3, 4, 7, 16})
#: SYS_STATUS sensor bits (present, enabled, healthy) as ArduSub SITL reports them in MANUAL with a GPS.
SENSORS = (0x1331FD2F, 0x12219D2F, 0x13319D2F)
#: Modes whose depth and position controllers ArduSub reports enabled and healthy (GCS_Sub.cpp).
CONTROLLED_MODES = frozenset({2, 3, 4, 7, 9, 16})
#: AUTOPILOT_VERSION: capabilities (MISSION_FLOAT/INT, PARAM_FLOAT, COMMAND_INT, SET_POSITION_TARGET_*,
#: MAVLINK2, MISSION_FENCE/RALLY, FTP, ...), version 4.7.0 dev and git hash of the firmware measured.
CAPABILITIES, SW_VERSION, GIT_HASH = 0xF9E7, 0x04070000, b"2598e9d4"
#: The three STATUSTEXT lines ArduPilot sends before the parameter list.
BANNER = (FIRMWARE, "RAPT simulated front-seat", "Frame: VECTORED")


class Vehicle(Protocol):
    """What the ground-station protocol needs from the vehicle it speaks for."""

    def vehicle_time(self) -> float:
        """Vehicle seconds since boot."""
        ...

    def mode_refusal(self, mode: int) -> str | None:
        """Why ``mode`` (an ArduSub mode) cannot be entered now, or None."""
        ...

    def enter_mode(self, mode: int) -> None: ...

    def arm_refusal(self, on: bool) -> str | None:
        """Why arming (or disarming) is refused now, or None."""
        ...

    def set_armed(self, on: bool) -> None: ...

    def send_on_request(self, name: str) -> bool:
        """Send one message (REQUEST_MESSAGE); False when the vehicle cannot send it now."""
        ...


def sensor_bits(mode: int, gps: bool) -> tuple[int, int, int]:
    """SYS_STATUS (present, enabled, healthy) as ArduSub sets them (GCS_Sub::update_vehicle_sensor_status_flags)."""
    present, enabled, health = SENSORS
    if mode in CONTROLLED_MODES:
        control = mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
        enabled, health = enabled | control, health | control
    if not gps:
        present, enabled, health = (bits & ~mav.MAV_SYS_STATUS_SENSOR_GPS for bits in (present, enabled, health))
    return present, enabled, health


def heartbeat_send(conn, mode: int, armed: bool) -> None:
    """ArduSub's HEARTBEAT (GCS_MAVLINK_Sub::base_mode, vehicle_system_status)."""
    base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
    base |= mav.MAV_MODE_FLAG_STABILIZE_ENABLED
    if mode in GUIDED_MODES:
        base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
    if armed:
        base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
    state = mav.MAV_STATE_ACTIVE if armed else mav.MAV_STATE_STANDBY
    conn.mav.heartbeat_send(mav.MAV_TYPE_SUBMARINE, mav.MAV_AUTOPILOT_ARDUPILOTMEGA, base, mode, state)


class GroundStationLink:
    """Answers a ground station's requests for one vehicle, as ArduSub does (see module docstring)."""

    def __init__(self, fs, vehicle: Vehicle, params: ParameterTable, streams: StreamSchedule):
        self.fs, self.vehicle, self.params, self.streams = fs, vehicle, params, streams
        #: Vehicle time the ground station's (MAV_GCS_SYSID) heartbeat was last heard; None before.
        self.gcs_heard: float | None = None
        self.ftp = ParamFileServer(params)
        self._texts: list[tuple[int, str]] = []  # STATUSTEXT sent after the COMMAND_ACK, as ArduSub orders them

    @property
    def conn(self):
        return self.fs.conn

    def handle(self, msg) -> bool:
        """Answer ``msg`` if it is a ground-station request; False when it is not one (set-points, missions)."""
        kind = msg.get_type()
        if kind == "HEARTBEAT":
            if msg.get_srcSystem() == int(self.params["MAV_GCS_SYSID"]):
                self.gcs_heard = self.vehicle.vehicle_time()
        elif kind == "COMMAND_LONG":
            self._command(msg)
        elif kind == "SET_MODE":
            self._set_mode(int(msg.base_mode) | mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, int(msg.custom_mode))
            self._flush_texts()
        elif kind == "PARAM_REQUEST_LIST":
            self._param_list()
        elif kind == "PARAM_REQUEST_READ":
            self._param_read(msg)
        elif kind == "PARAM_SET":
            self._param_set(msg)
        elif kind == "REQUEST_DATA_STREAM":
            self.streams.request_data_stream(
                int(msg.req_stream_id), int(msg.req_message_rate), msg.start_stop, self.vehicle.vehicle_time()
            )
        elif kind == "FILE_TRANSFER_PROTOCOL":
            self._ftp(msg)
        else:
            return False
        return True

    # -- commands ----------------------------------------------------------------------
    def _ack(self, msg, result: int) -> None:
        self.conn.mav.command_ack_send(int(msg.command), result, 0, 0, msg.get_srcSystem(), msg.get_srcComponent())

    def _flush_texts(self) -> None:
        for severity, text in self._texts:
            self.fs.send_status(severity, text)
        self._texts.clear()

    def _set_mode(self, base_mode: int, mode: int) -> int:
        if not base_mode & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mav.MAV_RESULT_DENIED
        if mode not in MODES:
            self._texts.append((mav.MAV_SEVERITY_WARNING, f"No such mode {mode}"))
            return mav.MAV_RESULT_FAILED
        refusal = self.vehicle.mode_refusal(mode)
        if refusal is not None:
            self._texts.append((mav.MAV_SEVERITY_WARNING, refusal))
            return mav.MAV_RESULT_FAILED
        self.vehicle.enter_mode(mode)
        return mav.MAV_RESULT_ACCEPTED

    def _command(self, msg) -> None:
        cmd, result = int(msg.command), mav.MAV_RESULT_ACCEPTED
        before: list = []  # what ArduSub sends before the ACK
        after: list = []  # ... and after it
        now = self.vehicle.vehicle_time()
        if cmd == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            if msg.param1 == 1.0 or msg.param1 == 0.0:
                on = msg.param1 == 1.0
                refusal = self.vehicle.arm_refusal(on)
                if refusal is not None:
                    self._texts.append((mav.MAV_SEVERITY_CRITICAL, refusal))
                    result = mav.MAV_RESULT_FAILED
                elif on != self.fs.armed:
                    self.vehicle.set_armed(on)
                    if on:  # ArduSub sets home where it arms, and says so
                        after += [lambda: self.vehicle.send_on_request("GPS_GLOBAL_ORIGIN")]
                        after += [lambda: self.vehicle.send_on_request("HOME_POSITION")]
                    self._texts.append((mav.MAV_SEVERITY_INFO, "Arming motors" if on else "Disarming motors"))
            else:
                result = mav.MAV_RESULT_UNSUPPORTED
        elif cmd == mav.MAV_CMD_DO_SET_MODE:
            result = self._set_mode(int(msg.param1), int(msg.param2))
        elif cmd == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            msg_id = int(msg.param1)
            result = self.streams.set_interval(msg_id, msg.param2, now)
            if result != mav.MAV_RESULT_ACCEPTED:
                self._texts.append((mav.MAV_SEVERITY_INFO, f"No ap_message for mavlink id ({msg_id})"))
        elif cmd == mav.MAV_CMD_GET_MESSAGE_INTERVAL:
            msg_id = int(msg.param1)
            us = self.streams.interval_us(msg_id)
            if us is None:
                result = mav.MAV_RESULT_FAILED
            else:
                before += [lambda: self.conn.mav.message_interval_send(msg_id, us)]
        elif cmd in (mav.MAV_CMD_REQUEST_MESSAGE, mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES):
            msg_id = int(msg.param1) if cmd == mav.MAV_CMD_REQUEST_MESSAGE else mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION
            name = _message_name(msg_id)
            if name is None or name not in _ON_REQUEST and self.streams.interval_us(msg_id) is None:
                result = mav.MAV_RESULT_FAILED
            else:
                after += [lambda: self._send_requested(name)]
        else:
            result = mav.MAV_RESULT_UNSUPPORTED
        for send in before:
            send()
        self._ack(msg, result)
        for send in after:
            send()
        self._flush_texts()

    def _send_requested(self, name: str) -> None:
        if name == "AUTOPILOT_VERSION":
            self.conn.mav.autopilot_version_send(
                CAPABILITIES, SW_VERSION, 0, 0, 0, list(GIT_HASH), [0] * 8, [0] * 8, 0, 0, 0
            )
        else:
            self.vehicle.send_on_request(name)

    # -- parameters --------------------------------------------------------------------
    def _param_value(self, name: str, index: int) -> None:
        p = self.params
        self.conn.mav.param_value_send(name.encode(), p[name], p.types[name], len(p), index & 0xFFFF)  # -1: 65535

    def _banner(self) -> None:
        """ArduPilot greets a parameter download (list or FTP) with these lines."""
        for text in BANNER:
            self.fs.send_status(mav.MAV_SEVERITY_INFO, text)

    def _param_list(self) -> None:
        self._banner()
        for i, name in enumerate(self.params.names):
            self._param_value(name, i)

    def _param_read(self, msg) -> None:
        index = int(msg.param_index)
        if index != -1:
            name = self.params.at(index)
        else:
            name = msg.param_id if msg.param_id in self.params else None
        if name is not None:  # ArduSub answers nothing for an unknown one
            self._param_value(name, index)

    def _param_set(self, msg) -> None:
        name = msg.param_id
        if self.params.set(name, float(msg.param_value)) is None:
            return  # unknown, NaN or infinite: ArduSub ignores it
        self._param_value(name, -1)
        if name.startswith("MAV1_"):
            self.streams.retime_all(self.vehicle.vehicle_time())

    # -- MAVLink FTP -------------------------------------------------------------------
    def _ftp(self, msg) -> None:
        payload = bytes(msg.payload)
        for reply in self.ftp.answer(payload):
            self.conn.mav.file_transfer_protocol_send(0, msg.get_srcSystem(), msg.get_srcComponent(), list(reply))
        if payload[3] == OPEN_RO and self.ftp.file is not None:
            self._banner()


def _message_name(msg_id: int) -> str | None:
    cls = mav.mavlink_map.get(int(msg_id))
    return None if cls is None else cls.msgname


#: Messages the vehicle sends only on request, beside the streamed ones.
_ON_REQUEST = frozenset({"AUTOPILOT_VERSION", "HOME_POSITION", "GPS_GLOBAL_ORIGIN"})
