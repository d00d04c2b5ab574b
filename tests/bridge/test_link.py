"""The MAVLink link against a minimal pymavlink vehicle: signing, reconnects, junk on the wire."""

from __future__ import annotations

import socket
import struct
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bridge import keys
from bridge.frames import mavlink2
from bridge.link import load_signing_key
from bridge.mavlink_bridge import MavlinkBridge
from tests.support.bridge_rig import (
    KEY,
    VEHICLE,
    Collector,
    FakeVehicle,
    bus,
    publisher,
    rig,
    setpoint,
    wait_for_subscriber,
)
from tests.support.loopback import free_port, wait_until

pytestmark = [pytest.mark.integration]


def test_signing_key_from_file(tmp_path):
    (tmp_path / "raw.key").write_bytes(KEY)
    (tmp_path / "hex.key").write_text(KEY.hex() + "\n")
    (tmp_path / "bad.key").write_text("not a key")
    assert load_signing_key(tmp_path / "raw.key") == KEY
    assert load_signing_key(str(tmp_path / "hex.key")) == KEY
    with pytest.raises(ValueError, match="signing_key") as info:
        load_signing_key(tmp_path / "bad.key")
    assert "not a key" not in str(info.value)


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
