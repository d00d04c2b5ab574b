"""The MAVLink bridge against a minimal pymavlink vehicle, over real loopback links and a real Zenoh session."""

from __future__ import annotations

import contextlib
import json
import os
import select
import socket
import struct
import threading
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")

import zenoh  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.command_gate import outward  # noqa: E402
from bridge.frames import FrameSplitter, is_signed, mavlink2, strip_signature  # noqa: E402
from bridge.link import load_signing_key  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.relay import TYPE_MASK_VELOCITY_YAW  # noqa: E402
from bridge.session import open_session, zenoh_config  # noqa: E402
from bridge.setpoint import Setpoint  # noqa: E402
from rapt.errors import LinkError, RefusedError  # noqa: E402

KEY = bytes(range(1, 33))
BURST = 10**12  # time_unix_usec of test frames, far from the vehicle clock (~1.8e15)
VEHICLE = "uuv1"


from tests.support.loopback import free_port, wait_until  # noqa: E402

pytestmark = [pytest.mark.integration]


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


# --------------------------------------------------------------------------- pure parts
def test_keys_follow_the_scheme():
    assert keys.telemetry("uuv1", "HEARTBEAT") == "rapt/uuv1/mavlink/HEARTBEAT"
    assert keys.raw("uuv1") == "rapt/uuv1/mavlink/raw"
    assert keys.command("uuv1", "*") == "rapt/uuv1/command/*"
    assert keys.virtual("uuv1", "OBSTACLE_DISTANCE_3D") == "rapt/uuv1/virtual/OBSTACLE_DISTANCE_3D"
    assert zenoh.KeyExpr(keys.everything("uuv1")).includes(keys.virtual("uuv1", "BATTERY_STATUS"))
    assert not zenoh.KeyExpr(keys.telemetry("uuv1", "*")).intersects(keys.virtual("uuv1", "*"))
    assert keys.active("uuv1") == "rapt/uuv1/control/active"
    assert keys.status("uuv1", "autonomy") == "rapt/uuv1/status/autonomy"
    assert keys.meta("uuv1", "scenario") == "rapt/uuv1/meta/scenario"
    assert keys.alive("uuv1", "bridge") == "rapt/uuv1/alive/bridge"
    assert keys.everything("uuv1") == "rapt/uuv1/**"
    assert zenoh.KeyExpr(keys.everything("uuv1")).includes(keys.command("uuv1", "x"))
    assert keys.split("rapt/uuv1/mavlink/HEARTBEAT") == ("uuv1", "mavlink", "HEARTBEAT")
    with pytest.raises(ValueError, match="vehicle"):
        keys.raw("a/b")
    with pytest.raises(ValueError, match="source"):
        keys.command("uuv1", "**")
    with pytest.raises(ValueError, match="msg_name"):
        keys.virtual("uuv1", "A/B")


def test_setpoint_validation_names_the_field():
    sp = Setpoint.from_json(b'{"tick_ms": 7, "vx": 1, "vy": 2.5, "vz": -0.5, "yaw": 0.1}')
    assert (sp.tick_ms, sp.vx, sp.vy, sp.vz, sp.yaw) == (7, 1.0, 2.5, -0.5, 0.1)
    assert Setpoint.from_json(sp.to_json()) == sp
    for payload, field in [
        (b'{"vx": 1, "vy": 2, "vz": 3}', "yaw"),
        (b'{"vx": NaN, "vy": 0, "vz": 0, "yaw": 0}', "vx"),
        (b'{"vx": 0, "vy": 0, "vz": 0, "yaw": 0, "tick_ms": -1}', "tick_ms"),
        (b"[1, 2]", "payload"),
        (b"\xff", "payload"),
    ]:
        with pytest.raises(ValueError, match=field):
            Setpoint.from_json(payload)


def test_outward_only_near_an_edge():
    fence = (0.0, 100.0, 0.0, 100.0)
    assert outward(fence, 20, 90, 50, 1.0, 0.0)
    assert not outward(fence, 20, 90, 50, -1.0, 0.0)
    assert not outward(fence, 20, 50, 50, 1.0, 1.0)
    assert outward(fence, 20, 50, 5, 0.0, -0.1)
    assert outward(fence, 20, 150, 50, 0.1, 0.0)  # outside, still heading out


def test_config_is_loopback_only_without_scouting():
    config = zenoh_config(listen=["tcp/127.0.0.1:7447"])
    assert json.loads(config.get_json("scouting/multicast/enabled")) is False
    assert json.loads(config.get_json("scouting/gossip/enabled")) is False
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:7447"]
    assert json.loads(config.get_json("connect/endpoints")) == []
    with pytest.raises(ValueError, match="listen"):
        zenoh_config(listen=["tcp/0.0.0.0:7447"])
    with pytest.raises(ValueError, match="connect"):
        zenoh_config(connect=["tcp/192.168.1.2:7447"])


def test_bad_arguments_are_named():
    with pytest.raises(ValueError, match="geofence"):
        MavlinkBridge("udpin:127.0.0.1:1", geofence=(10, 0, 0, 10))
    with pytest.raises(ValueError, match="max_rate_hz"):
        MavlinkBridge("udpin:127.0.0.1:1", max_rate_hz=0)
    with pytest.raises(ValueError, match="signing_key"):
        MavlinkBridge("udpin:127.0.0.1:1", signing_key=b"short")


def test_signing_key_from_file(tmp_path):
    (tmp_path / "raw.key").write_bytes(KEY)
    (tmp_path / "hex.key").write_text(KEY.hex() + "\n")
    (tmp_path / "bad.key").write_text("not a key")
    assert load_signing_key(tmp_path / "raw.key") == KEY
    assert load_signing_key(str(tmp_path / "hex.key")) == KEY
    with pytest.raises(ValueError, match="signing_key") as info:
        load_signing_key(tmp_path / "bad.key")
    assert "not a key" not in str(info.value)


def test_splitter_resynchronises_after_junk():
    mav = mavlink2.MAVLink(None, 1, 1)
    frames = [mavlink2.MAVLink_system_time_message(i, i).pack(mav) for i in range(3)]
    decoder = mavlink2.MAVLink(None, 2, 2)
    splitter = FrameSplitter(decoder.decode)
    corrupt = bytearray(frames[1])
    corrupt[12] ^= 0xFF
    # junk that claims a long frame (0xFD, len 255) must not swallow the real frames behind it
    stream = b"\x01\x02" + frames[0] + bytes(corrupt) + b"\xfd\xff\x00" + frames[2]
    got = splitter.feed(stream)
    got += splitter.resync()
    assert [m.time_boot_ms for _, m in got] == [0, 2]
    assert splitter.bad_frames >= 2 and splitter.pending == 0


def test_strip_signature_gives_a_valid_unsigned_frame():
    signer = mavlink2.MAVLink(None, 1, 1)
    signer.signing.secret_key = KEY
    signer.signing.sign_outgoing = True
    signer.signing.timestamp = 1
    frame = mavlink2.MAVLink_system_time_message(123, 456).pack(signer)
    assert is_signed(frame)
    stripped = strip_signature(frame)
    assert len(stripped) == len(frame) - 13 and not is_signed(stripped)
    msg = mavlink2.MAVLink(None, 2, 2).decode(bytearray(stripped))  # checks the recomputed CRC
    assert (msg.time_unix_usec, msg.time_boot_ms) == (123, 456)
    assert KEY not in stripped


# --------------------------------------------------------------------------- over the wire
def test_telemetry_json_and_raw_frames_in_order():
    with rig(rate_hz=20.0) as (bridge, vehicle, client, _):
        tel = Collector(client, keys.telemetry(VEHICLE, "*"))
        raw = Collector(client, keys.raw(VEHICLE))
        try:
            wait_until(lambda: tel.json(keys.telemetry(VEHICLE, "LOCAL_POSITION_NED")), what="telemetry")
            vehicle.position = (1.5, -2.0, 3.0)
            for i in range(300):  # a burst of numbered frames (paced: a UDP socket buffer holds ~200)
                vehicle.send(mavlink2.MAVLink_system_time_message(BURST + i, i))
                if i % 50 == 49:
                    time.sleep(0.01)
            key = keys.telemetry(VEHICLE, "SYSTEM_TIME")
            wait_until(lambda: any(d["time_unix_usec"] == BURST + 299 for d in tel.json(key)), what="the burst")
            wait_until(
                lambda: any(d["x"] == 1.5 for d in tel.json(keys.telemetry(VEHICLE, "LOCAL_POSITION_NED"))),
                what="the new position",
            )
            hb = tel.json(keys.telemetry(VEHICLE, "HEARTBEAT"))[-1]
            assert hb["mavpackettype"] == "HEARTBEAT" and hb["type"] == mavlink2.MAV_TYPE_SUBMARINE
            assert isinstance(hb["_recv_ns"], int) and abs(hb["_recv_ns"] - time.time_ns()) < 10**10
            pos = [d for d in tel.json(keys.telemetry(VEHICLE, "LOCAL_POSITION_NED")) if d["x"] == 1.5][-1]
            assert (pos["y"], pos["z"]) == (-2.0, 3.0)
            # raw: the burst arrives complete and in order, byte-identical frames
            parser = mavlink2.MAVLink(None, 9, 9)
            msgs = [parser.decode(bytearray(p)) for _, _, p in raw.items()]
            burst = [
                m.time_boot_ms for m in msgs if m.get_type() == "SYSTEM_TIME" and BURST <= m.time_unix_usec < 2 * BURST
            ]
            assert burst == list(range(300))
            assert bridge.stats["bad_frames"] == 0 and bridge.stats["frames_in"] >= 300
            assert bridge.target == (1, 1) and bridge.linked
        finally:
            tel.close()
            raw.close()


def test_active_source_commands_reach_the_vehicle_others_do_not():
    with rig(allow_commands=True) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        autonomy = publisher(client, keys.command(VEHICLE, "autonomy"))
        operator = client.declare_publisher(keys.command(VEHICLE, "operator"), express=True)
        operator.put(setpoint(vx=9.0, tick_ms=1))
        autonomy.put(setpoint(vx=0.5, vy=-0.25, vz=-0.1, yaw=1.0, tick_ms=42))
        got = wait_until(lambda: vehicle.messages("SET_POSITION_TARGET_LOCAL_NED"), what="the set-point")
        assert len(got) == 1  # the operator's came first and was not forwarded
        m = got[0]
        assert (m.time_boot_ms, m.target_system, m.target_component) == (42, 1, 1)
        assert m.coordinate_frame == mavlink2.MAV_FRAME_LOCAL_NED and m.type_mask == TYPE_MASK_VELOCITY_YAW == 2503
        assert (m.x, m.y, m.z, m.afx, m.afy, m.afz, m.yaw_rate) == (0, 0, 0, 0, 0, 0, 0)
        assert (m.vx, m.vy, m.vz) == pytest.approx((0.5, -0.25, -0.1)) and m.yaw == pytest.approx(1.0)
        assert m.get_srcSystem() == 1 and m.get_srcComponent() == mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER
        assert bridge.stats["commands_inactive"] == 1
        # hand control to the operator: now only the operator's set-points go through
        client.put(keys.active(VEHICLE), "operator")
        autonomy.put(setpoint(tick_ms=2))
        operator.put(setpoint(vx=0.75, tick_ms=3))
        wait_until(lambda: len(vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")) == 2, what="the operator's")
        assert [m.time_boot_ms for m in vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")] == [42, 3]
        assert bridge.active == "operator" and bridge.stats["commands_inactive"] == 2
        operator.undeclare()
        autonomy.undeclare()


def test_nothing_but_heartbeats_without_allow_commands():
    with rig(allow_commands=False) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        pub = publisher(client, keys.command(VEHICLE, "autonomy"))
        for i in range(5):
            pub.put(setpoint(tick_ms=i))
        wait_until(lambda: bridge.stats["commands_refused"] == 5, what="refusals")
        with pytest.raises(RefusedError, match="allow_commands"):  # a PermissionError, as before
            bridge.arm(True)
        with pytest.raises(RefusedError, match="allow_commands"):
            bridge.set_mode("GUIDED")
        wait_until(lambda: vehicle.messages("HEARTBEAT"), what="the bridge's heartbeat")
        time.sleep(0.1)
        names = {m.get_type() for m in vehicle.received}
        assert names == {"HEARTBEAT"}
        hb = vehicle.messages("HEARTBEAT")[0]
        assert (hb.type, hb.autopilot) == (mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID)
        assert bridge.stats["commands_forwarded"] == 0
        pub.undeclare()


def test_arm_and_set_mode_wait_for_the_ack():
    with rig(allow_commands=True) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        assert bridge.set_mode("guided") == mavlink2.MAV_RESULT_ACCEPTED
        assert vehicle.custom_mode == 4
        assert bridge.arm(True) == mavlink2.MAV_RESULT_ACCEPTED and vehicle.armed
        (cmd,) = [m for m in vehicle.messages("COMMAND_LONG") if m.command == mavlink2.MAV_CMD_DO_SET_MODE]
        assert (cmd.param1, cmd.param2) == (mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, 4)
        with pytest.raises(ValueError, match="mode"):
            bridge.set_mode("WARP")


def test_geofence_refuses_outward_commands_near_the_edge():
    fence = (0.0, 100.0, 0.0, 100.0)
    with rig(allow_commands=True, geofence=fence, position=(90.0, 50.0, 5.0)) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked and bridge._relay.position is not None, what="a position")
        pub = publisher(client, keys.command(VEHICLE, "autonomy"))
        pub.put(setpoint(vx=1.0, vy=0.0, tick_ms=1))  # out through the north edge: refused
        pub.put(setpoint(vx=0.2, vy=0.3, tick_ms=2))  # still outward (north component): refused
        pub.put(setpoint(vx=-1.0, vy=0.0, tick_ms=3))  # back inside: forwarded
        pub.put(setpoint(vx=0.0, vy=1.0, tick_ms=4))  # along the edge, east is far: forwarded
        wait_until(lambda: len(vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")) == 2, what="two set-points")
        assert [m.time_boot_ms for m in vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")] == [3, 4]
        assert bridge.stats["commands_geofence"] == 2
        pub.undeclare()


def test_rate_limit_drops_the_excess():
    with rig(allow_commands=True, max_rate_hz=2.0) as (bridge, vehicle, client, _):
        wait_until(lambda: bridge.linked, what="the bridge to hear the vehicle")
        pub = publisher(client, keys.command(VEHICLE, "autonomy"))
        for i in range(40):
            pub.put(setpoint(tick_ms=i))
        wait_until(lambda: bridge.stats["commands_in"] == 40, what="all commands")
        s = bridge.stats
        assert s["commands_forwarded"] + s["commands_rate_limited"] == 40
        assert 1 <= s["commands_forwarded"] <= 2 and s["commands_rate_limited"] >= 38
        wait_until(
            lambda: len(vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")) == s["commands_forwarded"],
            what="the forwarded set-points",
        )
        assert vehicle.messages("SET_POSITION_TARGET_LOCAL_NED")[0].time_boot_ms == 0
        pub.undeclare()


def test_signing_refuses_unsigned_and_passes_signed():
    with rig(signing_key=KEY) as (bridge, vehicle, client, port):
        tel = Collector(client, keys.telemetry(VEHICLE, "*"))
        everything = Collector(client, keys.everything(VEHICLE))
        try:
            wait_until(lambda: bridge.stats["unsigned_refused"] >= 10, what="unsigned frames to be refused")
            assert bridge.stats["frames_in"] == 0 and not tel.items() and not bridge.linked
            vehicle.close()
            # a vehicle with the wrong key is refused too
            wrong = FakeVehicle(f"udpout:127.0.0.1:{port}", signing_key=bytes(32))
            try:
                wait_until(lambda: bridge.stats["bad_signature"] >= 5, what="badly signed frames to be refused")
            finally:
                wrong.close()
            assert bridge.stats["frames_in"] == 0 and not tel.items()
            signed = FakeVehicle(f"udpout:127.0.0.1:{port}", signing_key=KEY)
            try:
                wait_until(lambda: tel.json(keys.telemetry(VEHICLE, "SYSTEM_TIME")), what="signed telemetry")
                # the bridge signs what it sends: the signed vehicle accepts its heartbeat
                hb = wait_until(lambda: signed.messages("HEARTBEAT"), what="a signed heartbeat")[0]
                assert hb._signed
                assert signed.conn.mav.signing.goodsig_count >= 1
            finally:
                signed.close()
            assert everything.items() and not any(KEY in p or KEY.hex().encode() in p for _, _, p in everything.items())
        finally:
            tel.close()
            everything.close()
        assert KEY.hex() not in repr(bridge)


def test_reconnect_after_the_vehicle_restarts():
    port = free_port()
    with bus() as (hub, client, _):
        tel = Collector(client, keys.telemetry(VEHICLE, "SYSTEM_TIME"))
        vehicle = FakeVehicle(f"tcpin:127.0.0.1:{port}")
        try:
            with MavlinkBridge(
                f"tcp:127.0.0.1:{port}", hub, vehicle=VEHICLE, silence_s=0.5, allow_commands=True
            ) as bridge:
                wait_until(lambda: tel.items(), what="first telemetry")
                vehicle.close()
                wait_until(lambda: not bridge.linked, what="the link loss")
                count = len(tel.items())
                time.sleep(0.3)
                assert len(tel.items()) == count  # nothing stale is published while the vehicle is away
                pub = publisher(client, keys.command(VEHICLE, "autonomy"))
                pub.put(setpoint(tick_ms=5))
                wait_until(lambda: bridge.stats["commands_stale"] == 1, what="a command refused while silent")
                vehicle = FakeVehicle(f"tcpin:127.0.0.1:{port}")
                wait_until(lambda: len(tel.items()) > count + 3, timeout=10, what="telemetry to resume")
                assert bridge.stats["reconnects"] == 1 and bridge.stats["link_losses"] == 1
                wait_until(lambda: bridge.linked, what="the link")
                pub.put(setpoint(tick_ms=6))
                got = wait_until(lambda: vehicle.messages("SET_POSITION_TARGET_LOCAL_NED"), what="a set-point")
                assert [m.time_boot_ms for m in got] == [6]
                pub.undeclare()
        finally:
            vehicle.close()
            tel.close()


def test_silent_udp_vehicle_counts_as_a_reconnect():
    with rig(silence_s=0.3) as (bridge, vehicle, client, port):
        wait_until(lambda: bridge.linked, what="the link")
        vehicle.close()
        wait_until(lambda: bridge.stats["link_losses"] == 1, what="silence to be noticed")
        assert not bridge.linked
        again = FakeVehicle(f"udpout:127.0.0.1:{port}")
        try:
            wait_until(lambda: bridge.stats["reconnects"] == 1 and bridge.linked, what="the link to resume")
        finally:
            again.close()


def _valid_frames():
    mav = mavlink2.MAVLink(None, 1, 1)
    return [
        mavlink2.MAVLink_system_time_message(7, 8).pack(mav),
        mavlink2.MAVLink_heartbeat_message(12, 3, 0, 0, 4, 3).pack(mav),
        mavlink2.MAVLink_local_position_ned_message(1, 2.0, 3.0, 4.0, 0.0, 0.0, 0.0).pack(mav),
    ]


@st.composite
def corrupted_frames(draw):
    frame = bytearray(draw(st.sampled_from(_valid_frames())))
    how = draw(st.sampled_from(["flip", "truncate", "prefix"]))
    if how == "flip":
        i = draw(st.integers(0, len(frame) - 1))
        frame[i] ^= draw(st.integers(1, 255))
    elif how == "truncate":
        frame = frame[: draw(st.integers(1, len(frame) - 1))]
    else:
        frame = bytearray(draw(st.binary(min_size=1, max_size=20))) + frame[:-1]
    return bytes(frame)


def test_fuzzed_datagrams_are_counted_and_skipped():
    with rig(rate_hz=5.0) as (bridge, vehicle, client, port):
        wait_until(lambda: bridge.linked, what="the link")
        tel = Collector(client, keys.telemetry(VEHICLE, "SYSTEM_TIME"))
        sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        mav = mavlink2.MAVLink(None, 1, 1)
        marker = iter(range(1, 10**9))
        try:

            @settings(max_examples=120, deadline=None, suppress_health_check=list(HealthCheck), database=None)
            @given(junk=st.one_of(st.binary(min_size=1, max_size=400), corrupted_frames()))
            def check(junk):
                before = bridge.stats["bad_frames"]
                sender.sendto(junk, ("127.0.0.1", port))
                n = next(marker)
                sender.sendto(mavlink2.MAVLink_system_time_message(n, 0).pack(mav), ("127.0.0.1", port))
                wait_until(
                    lambda: any(b'"time_unix_usec":%d,' % n in p for _, _, p in tel.items()),
                    what="the valid frame after junk",
                )
                assert bridge.stats["bad_frames"] >= before + 1

            check()
            # junk and a valid frame in one datagram: the frame is still found
            sender.sendto(b"\x00\xfd\x05" + mavlink2.MAVLink_system_time_message(777, 0).pack(mav), ("127.0.0.1", port))
            wait_until(lambda: any(b'"time_unix_usec":777,' in p for _, _, p in tel.items()), what="frame in junk")
            assert bridge._threads[0].is_alive()
        finally:
            sender.close()
            tel.close()


def test_junk_on_a_tcp_stream_does_not_swallow_frames():
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)
    port = server.getsockname()[1]
    mav = mavlink2.MAVLink(None, 1, 1)
    with bus() as (hub, client, _):
        tel = Collector(client, keys.telemetry(VEHICLE, "SYSTEM_TIME"))
        try:
            wait_for_subscriber(hub, keys.telemetry(VEHICLE, "SYSTEM_TIME"))  # or the hub may drop the first frame
            with MavlinkBridge(f"tcp:127.0.0.1:{port}", hub, vehicle=VEHICLE) as bridge:
                conn, _ = server.accept()
                with conn:
                    frames = [mavlink2.MAVLink_system_time_message(i, i).pack(mav) for i in range(5)]
                    conn.sendall(frames[0] + b"\xfd\xff\x00\x00" + frames[1] + struct.pack("<H", 0xBEEF) + frames[2])
                    conn.sendall(b"junk\xfe\xff")  # a partial 'frame', then silence
                    wait_until(lambda: len(tel.items()) == 3, what="the three frames")
                    conn.sendall(frames[3] + frames[4])
                    wait_until(lambda: len(tel.items()) == 5, what="frames after the stall")
                    boots = [d["time_boot_ms"] for d in tel.json(keys.telemetry(VEHICLE, "SYSTEM_TIME"))]
                    assert boots == list(range(5))
                    assert bridge.stats["bad_frames"] >= 2
        finally:
            tel.close()
            server.close()


def test_liveliness_token_while_running():
    with bus() as (hub, client, _):
        alive = Collector(client, keys.alive(VEHICLE, "*"), liveliness=True)
        try:
            with MavlinkBridge(f"udpin:127.0.0.1:{free_port(socket.SOCK_DGRAM)}", hub, vehicle=VEHICLE):
                wait_until(lambda: alive.items(), what="the token")

                # A late joiner's query finds the token.  Asked again until it does: in the full suite
                # on a loaded machine one query in a few runs came back empty at once (eclipse-zenoh
                # 1.10), while the subscriber above had the token; the token itself is never missing.
                def tokens():
                    replies = client.liveliness().get(keys.alive(VEHICLE, "*"), timeout=2)
                    return [str(r.ok.key_expr) for r in replies if r.ok]

                found = wait_until(tokens, timeout=10, what="a liveliness query to find the token")
                assert found == [keys.alive(VEHICLE, "bridge")]
            # The token goes once the bridge closes.  Waited for up to 15 s, and a repeated PUT before it
            # is allowed: in a fresh-clone suite run beside the main job (both cores oversubscribed) the
            # wait for exactly [PUT, DELETE] timed out once.  A history=True subscriber asks for the
            # tokens alive as it is declared, so a token declared while that query is in flight may
            # arrive twice; what matters is that it was there and is gone.
            gone = lambda: any(kind == zenoh.SampleKind.DELETE for _, kind, _ in alive.items())  # noqa: E731
            try:
                wait_until(gone, timeout=15, what="the token to go")
            except AssertionError:
                raise AssertionError(f"the token did not go in 15 s; samples: {alive.items()}") from None
            items = alive.items()
            kinds = [kind for _, kind, _ in items]
            assert kinds[0] == zenoh.SampleKind.PUT and kinds[-1] == zenoh.SampleKind.DELETE, items
            assert kinds.count(zenoh.SampleKind.DELETE) == 1, items
            assert {key for key, _, _ in items} == {keys.alive(VEHICLE, "bridge")}, items
        finally:
            alive.close()


def test_a_client_waits_for_a_hub_that_starts_later_and_names_a_missing_one():
    import threading

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    holder = {}

    def start_hub_late():
        time.sleep(1.0)
        holder["hub"] = open_session(listen=[endpoint])

    starter = threading.Thread(target=start_hub_late)
    starter.start()
    client = open_session(connect=[endpoint], connect_timeout=8)  # blocks until the hub is up
    starter.join()
    try:
        wait_until(lambda: list(client.info.peers_zid()), what="the late hub")
    finally:
        client.close()
        holder["hub"].close()
    nobody = f"tcp/127.0.0.1:{free_port()}"
    started = time.monotonic()
    with pytest.raises(LinkError, match=f"could not open the session \\({nobody}\\).*start the hub"):
        open_session(connect=[nobody], connect_timeout=0.5)
    assert time.monotonic() - started < 5
