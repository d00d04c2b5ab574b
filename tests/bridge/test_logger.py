"""The MCAP logger on a real loopback bus: what it writes, what survives SIGKILL, and that it loses nothing."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.reader import make_reader

from bridge import keys
from bridge.frames import is_signed, mavlink2
from bridge.logger import RAW_TOPIC, McapLogger, read_log, read_metadata
from bridge.mavlink_bridge import MavlinkBridge
from bridge.session import open_session
from tests.support.bridge_rig import KEY, VEHICLE, FakeVehicle, bus, publisher, setpoint
from tests.support.loopback import free_port, wait_until

pytestmark = [pytest.mark.integration]

ROOT = Path(__file__).resolve().parents[2]


def _log_a_signed_run(path: Path) -> tuple[dict, int, list]:
    """A signed vehicle, the bridge and the logger on one bus; meta, status and two sources' set-points put.

    Returns the logger's stats, the frames the bridge received and the set-points the vehicle got."""
    port = free_port(socket.SOCK_DGRAM)
    with bus() as (hub, client, endpoint):
        logger_session = open_session(connect=[endpoint])
        try:
            logger = McapLogger(path, logger_session, vehicle=VEHICLE, flush_interval_s=0.2).start()
            try:
                wait_until(lambda: logger.stats["written"] >= 1, what="the logger's own token")
                bridge = MavlinkBridge(
                    f"udpin:127.0.0.1:{port}", hub, vehicle=VEHICLE, allow_commands=True, signing_key=KEY
                ).start()
                vehicle = FakeVehicle(f"udpout:127.0.0.1:{port}", signing_key=KEY)
                try:
                    wait_until(lambda: bridge.linked, what="the bridge to hear the signed vehicle")
                    scenario = {
                        "scenario_id": 7,
                        "mission_file": "examples/range2017.toml",
                        "parameters": {"battery": 0.8},
                        "plan_id": "p-1",
                    }
                    client.put(keys.meta(VEHICLE, "scenario"), json.dumps(scenario))
                    client.put(keys.status(VEHICLE, "autonomy"), json.dumps({"state": "transit", "leg": 2}))
                    client.put(keys.status(VEHICLE, "odd"), b"\xff\x00")
                    operator = client.declare_publisher(keys.command(VEHICLE, "operator"))
                    autonomy = publisher(client, keys.command(VEHICLE, "autonomy"))
                    operator.put(setpoint(vx=9.0, tick_ms=1))
                    autonomy.put(setpoint(vx=0.5, tick_ms=2))
                    got = wait_until(lambda: vehicle.messages("SET_POSITION_TARGET_LOCAL_NED"), what="the set-point")
                    operator.undeclare()
                    autonomy.undeclare()
                finally:
                    vehicle.close()
                    bridge.close()
                frames_in = bridge.stats["frames_in"]
                wait_until(
                    lambda: any(
                        t == keys.alive(VEHICLE, "bridge") and p == {"alive": False} for t, _, p in read_log(path)
                    ),
                    what="the bridge's token to go (flushed)",
                )
            finally:
                logger.close()
            stats = logger.stats
        finally:
            logger_session.close()
    return stats, frames_in, got


def test_logger_writes_channels_stripped_raw_frames_and_metadata(tmp_path):
    path = tmp_path / "run.mcap"
    stats, frames_in, got = _log_a_signed_run(path)
    assert [m.time_boot_ms for m in got] == [2]

    assert stats["errors"] == 0 and stats["written"] == stats["received"] and stats["metadata"] == 1
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.topic: c for c in summary.channels.values()}
        for topic in (
            keys.telemetry(VEHICLE, "HEARTBEAT"),
            keys.telemetry(VEHICLE, "LOCAL_POSITION_NED"),
            keys.command(VEHICLE, "autonomy"),
            keys.command(VEHICLE, "operator"),
            keys.meta(VEHICLE, "scenario"),
            keys.status(VEHICLE, "autonomy"),
            keys.alive(VEHICLE, "bridge"),
        ):
            assert channels[topic].message_encoding == "json"
            schema = summary.schemas[channels[topic].schema_id]
            assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
        assert channels[RAW_TOPIC].schema_id == 0
        assert summary.statistics.message_count == stats["written"] + stats["derived"]  # + the Foxglove ones

    messages = read_log(path)
    by_topic: dict[str, list] = {}
    for topic, _, payload in messages:
        by_topic.setdefault(topic, []).append(payload)
    # raw: every frame the bridge received, signatures stripped, still valid MAVLink
    raw = by_topic[RAW_TOPIC]
    assert len(raw) == frames_in
    parser = mavlink2.MAVLink(None, 9, 9)
    decoded = [parser.decode(bytearray(frame)) for frame in raw]
    assert not any(is_signed(frame) for frame in raw) and KEY not in b"".join(raw)
    assert {m.get_type() for m in decoded} >= {"HEARTBEAT", "LOCAL_POSITION_NED", "SYSTEM_TIME"}
    hb = by_topic[keys.telemetry(VEHICLE, "HEARTBEAT")][0]
    assert hb["type"] == mavlink2.MAV_TYPE_SUBMARINE and isinstance(hb["_recv_ns"], int)
    # both sources' commands are recorded, though only the active one was forwarded
    assert [c["vx"] for c in by_topic[keys.command(VEHICLE, "operator")]] == [9.0]
    assert [c["tick_ms"] for c in by_topic[keys.command(VEHICLE, "autonomy")]] == [2]
    assert by_topic[keys.status(VEHICLE, "autonomy")] == [{"state": "transit", "leg": 2}]
    assert by_topic[keys.status(VEHICLE, "odd")] == [{"base64": "/wA="}]
    assert by_topic[keys.alive(VEHICLE, "bridge")] == [{"alive": True}, {"alive": False}]
    assert by_topic[keys.meta(VEHICLE, "scenario")][0]["plan_id"] == "p-1"
    meta = read_metadata(path)["scenario"]
    assert meta == {
        "scenario_id": "7",
        "mission_file": "examples/range2017.toml",
        "parameters": '{"battery": 0.8}',
        "plan_id": "p-1",
    }


def test_sigkilled_logger_leaves_a_readable_file(tmp_path):
    path = tmp_path / "killed.mcap"
    with bus() as (hub, client, endpoint):
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "bridge.logger",
                str(path),
                "--vehicle",
                VEHICLE,
                "--connect",
                endpoint,
                "--flush-interval",
                "0.1",
                "--chunk-size",
                "4096",
            ],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        try:
            assert proc.stdout.readline().strip() == "ready"
            pub = publisher(client, keys.status(VEHICLE, "autonomy"))
            client.put(keys.meta(VEHICLE, "scenario"), json.dumps({"scenario_id": 3}))
            for i in range(2000):
                pub.put(json.dumps({"i": i, "pad": "x" * 64}))
            time.sleep(1.0)  # ten flush intervals: everything so far is on disk
            for i in range(2000, 2500):  # some of these may be in the open chunk when the logger dies
                pub.put(json.dumps({"i": i, "pad": "x" * 64}))
            proc.send_signal(signal.SIGKILL)
            proc.wait(timeout=10)
            pub.undeclare()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait(timeout=10)
            proc.stdout.close()
    assert proc.returncode == -signal.SIGKILL
    with open(path, "rb") as f, pytest.raises(McapError):
        make_reader(f).get_summary()  # no footer: the normal reader gives up
    statuses = [p["i"] for t, _, p in read_log(path) if t == keys.status(VEHICLE, "autonomy")]
    assert statuses == list(range(len(statuses))) and 2000 <= len(statuses) <= 2500
    assert read_metadata(path)["scenario"] == {"scenario_id": "3"}


def test_no_loss_in_a_burst(tmp_path):
    path = tmp_path / "burst.mcap"
    n = 5000
    with bus() as (hub, client, endpoint):
        with McapLogger(path, hub, vehicle=VEHICLE) as logger:
            # The logger's own liveliness token is a message too: count from after it, or the wait
            # below ends one sample early and closing can cut off the last one still in flight.
            wait_until(lambda: logger.stats["written"] >= 1, what="the logger's own token")
            before = logger.stats["written"]
            pub = publisher(client, keys.status(VEHICLE, "autonomy"))
            start = time.monotonic()
            for i in range(n):
                pub.put(json.dumps({"i": i, "depth": 3.25, "mode": "transit"}))
            elapsed = time.monotonic() - start
            wait_until(lambda: logger.stats["written"] >= before + n, timeout=30, what="every message to be written")
            pub.undeclare()
        stats = logger.stats
    assert stats["errors"] == 0 and stats["queued"] == 0
    got = [p["i"] for t, _, p in read_log(path) if t == keys.status(VEHICLE, "autonomy")]
    assert got == list(range(n)), f"published {n} in {elapsed:.2f} s, logged {len(got)}"


def test_logger_arguments_are_named(tmp_path):
    with pytest.raises(ValueError, match="flush_interval_s"):
        McapLogger(tmp_path / "x.mcap", flush_interval_s=0)
    with pytest.raises(ValueError, match="compression"):
        McapLogger(tmp_path / "x.mcap", compression="gzip")
    with pytest.raises(ValueError, match="vehicle"):
        McapLogger(tmp_path / "x.mcap", vehicle="a/b")


def test_liveliness_of_processes_is_logged(tmp_path):
    path = tmp_path / "alive.mcap"
    with bus() as (hub, client, endpoint):
        with McapLogger(path, hub, vehicle=VEHICLE, flush_interval_s=0.1) as logger:
            token = client.liveliness().declare_token(keys.alive(VEHICLE, "autonomy"))
            wait_until(lambda: logger.stats["received"] >= 2, what="the token")  # its own + autonomy
            token.undeclare()
            wait_until(lambda: logger.stats["received"] >= 3, what="the token to go")
            replies = list(client.liveliness().get(keys.alive(VEHICLE, "*"), timeout=2))
            assert [str(r.ok.key_expr) for r in replies if r.ok] == [keys.alive(VEHICLE, "logger")]
    changes = [(t, p["alive"]) for t, _, p in read_log(path)]
    assert changes.count((keys.alive(VEHICLE, "autonomy"), True)) == 1
    assert changes.index((keys.alive(VEHICLE, "autonomy"), True)) < changes.index(
        (keys.alive(VEHICLE, "autonomy"), False)
    )
