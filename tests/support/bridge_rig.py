"""A minimal pymavlink vehicle, a bus of two loopback Zenoh sessions and the bridge between: the bridge tests' rig."""

from __future__ import annotations

import contextlib
import json
import os
import select
import socket
import threading
import time

os.environ.setdefault("MAVLINK20", "1")

import zenoh  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from bridge.frames import mavlink2  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.session import open_session  # noqa: E402
from bridge.setpoint import Setpoint  # noqa: E402
from tests.support.loopback import free_port, wait_until  # noqa: E402

KEY = bytes(range(1, 33))
BURST = 10**12  # time_unix_usec of test frames, far from the vehicle clock (~1.8e15)
VEHICLE = "uuv1"


class FakeVehicle:
    """A minimal ArduSub front-seat: HEARTBEAT (submarine, ArduPilotMega), LOCAL_POSITION_NED and
    SYSTEM_TIME at ``rate_hz``; answers COMMAND_LONG with COMMAND_ACK; records what it receives."""

    def __init__(self, device, *, rate_hz=50.0, signing_key=None, position=(0.0, 0.0, 5.0), sysid=1, compid=1):
        self.conn = mavutil.mavlink_connection(
            device, source_system=sysid, source_component=compid, dialect="ardupilotmega"
        )
        if signing_key is not None:
            self.conn.setup_signing(signing_key, sign_outgoing=True)
        self.position = position
        self.rate_hz = rate_hz
        self.received: list = []
        self.custom_mode = 19
        self.armed = False
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._boot = time.monotonic()
        self._thread = threading.Thread(target=self._loop, name="fake-vehicle", daemon=True)
        self._thread.start()

    def time_boot_ms(self) -> int:
        return int((time.monotonic() - self._boot) * 1000)

    def send(self, msg) -> None:
        with self._lock:
            self.conn.mav.send(msg)

    def send_telemetry(self) -> None:
        m = mavlink2
        base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (m.MAV_MODE_FLAG_SAFETY_ARMED if self.armed else 0)
        self.send(
            m.MAVLink_heartbeat_message(
                m.MAV_TYPE_SUBMARINE, m.MAV_AUTOPILOT_ARDUPILOTMEGA, base, self.custom_mode, m.MAV_STATE_ACTIVE, 3
            )
        )
        x, y, z = self.position
        t = self.time_boot_ms()
        self.send(m.MAVLink_local_position_ned_message(t, x, y, z, 0.0, 0.0, 0.0))
        self.send(m.MAVLink_system_time_message(time.time_ns() // 1000, t))

    def messages(self, name: str) -> list:
        with self._lock:
            return [msg for msg in self.received if msg.get_type() == name]

    def _handle(self, msg) -> None:
        name = msg.get_type()
        if name == "BAD_DATA":
            return
        with self._lock:
            self.received.append(msg)
        if name == "COMMAND_LONG":
            if msg.command == mavlink2.MAV_CMD_DO_SET_MODE:
                self.custom_mode = int(msg.param2)
            elif msg.command == mavlink2.MAV_CMD_COMPONENT_ARM_DISARM:
                self.armed = msg.param1 == 1.0
            self.send(
                mavlink2.MAVLink_command_ack_message(
                    msg.command, mavlink2.MAV_RESULT_ACCEPTED, 0, 0, msg.get_srcSystem(), msg.get_srcComponent()
                )
            )

    def _loop(self) -> None:
        period = 1.0 / self.rate_hz
        next_send = time.monotonic()
        while not self._stop.is_set():
            now = time.monotonic()
            if now >= next_send:
                try:
                    self.send_telemetry()
                except OSError:
                    pass
                next_send = now + period
            try:
                fd = self.conn.fd
                if fd is None or not select.select([fd], [], [], max(0.0, min(0.02, next_send - now)))[0]:
                    continue
                while (msg := self.conn.recv_msg()) is not None:
                    self._handle(msg)
            except (OSError, ValueError):
                time.sleep(0.01)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self.conn.close()


class Collector:
    """A Zenoh subscriber (FIFO channel) drained by its own thread into a list."""

    def __init__(self, session, key: str, *, liveliness: bool = False):
        if liveliness:
            self.sub = session.liveliness().declare_subscriber(key, history=True)
        else:
            self.sub = session.declare_subscriber(key, zenoh.handlers.FifoChannel(100_000))
        self._handler = self.sub.handler
        self.samples: list = []
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            try:
                s = self._handler.recv()
            except zenoh.ZError:
                return
            item = (str(s.key_expr), s.kind, s.payload.to_bytes())
            with self._lock:
                self.samples.append(item)

    def items(self, key: str | None = None) -> list:
        with self._lock:
            return [s for s in self.samples if key is None or s[0] == key]

    def json(self, key: str) -> list[dict]:
        return [json.loads(p) for k, kind, p in self.items(key) if kind == zenoh.SampleKind.PUT]

    def close(self) -> None:
        self.sub.undeclare()
        self._thread.join(timeout=5)


@contextlib.contextmanager
def bus():
    """A hub session (the bridge's) and a client session (the back-seat's), both on loopback."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    hub = open_session(listen=[endpoint])
    client = open_session(connect=[endpoint])
    try:
        wait_until(lambda: list(client.info.peers_zid()), what="the Zenoh client to connect")
        yield hub, client, endpoint
    finally:
        client.close()
        hub.close()


def publisher(session, key: str):
    pub = session.declare_publisher(key, express=True, congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: pub.matching_status.matching, what=f"a subscriber for {key}")
    return pub


def wait_for_subscriber(session, key: str) -> None:
    """Wait until ``session`` routes ``key`` to a subscriber: until its declaration has reached ``session``.

    A sample put before then is dropped, not queued (eclipse-zenoh 1.10), so a test that counts every
    sample a bridge on ``session`` publishes waits here first. A probe publisher's matching status
    says when ``session`` knows the subscriber; the probe itself never puts anything.
    """
    probe = session.declare_publisher(key)
    try:
        wait_until(lambda: probe.matching_status.matching, what=f"a subscriber for {key} to reach the session")
    finally:
        probe.undeclare()


def setpoint(vx=0.5, vy=-0.25, vz=-0.1, yaw=1.0, tick_ms=None) -> bytes:
    return Setpoint(vx, vy, vz, yaw, tick_ms).to_json()


@contextlib.contextmanager
def rig(*, signing_key=None, vehicle_key=None, position=(0.0, 0.0, 5.0), rate_hz=50.0, **bridge_kw):
    """Vehicle on udpout -> bridge on udpin, Zenoh hub + client; everything closed afterwards."""
    port = free_port(socket.SOCK_DGRAM)
    with bus() as (hub, client, endpoint):
        bridge = MavlinkBridge(
            f"udpin:127.0.0.1:{port}", hub, vehicle=VEHICLE, signing_key=signing_key, heartbeat_hz=20.0, **bridge_kw
        )
        vehicle = None
        try:
            bridge.start()
            vehicle = FakeVehicle(
                f"udpout:127.0.0.1:{port}", signing_key=vehicle_key, position=position, rate_hz=rate_hz
            )
            yield bridge, vehicle, client, port
        finally:
            if vehicle is not None:
                vehicle.close()
            bridge.close()
