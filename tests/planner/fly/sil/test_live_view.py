"""A SIL run watched live, as the range crew would in Foxglove: a Python client (``websockets``) and Foxglove's
TypeScript client (``@foxglove/ws-protocol``) both subscribed while the run flies, both shown what the log holds."""

from __future__ import annotations

import json
import socket
import threading
import time
from pathlib import Path

import pytest
from websockets.exceptions import InvalidHandshake

from bridge import foxglove, keys
from bridge.logger import read_log
from planner.fly.flight import flight_from_plan
from planner.fly.sil.rehearse import fly
from tests.support.foxglove_check import foxglove_channels, typescript_report, watch_with_typescript
from tests.support.foxglove_client import SUBPROTOCOL, FoxgloveClient
from tests.support.loopback import free_port

pytestmark = [pytest.mark.slow, pytest.mark.integration]  # a 30 s flight; tests/bridge/test_live_view.py is fast

PLAN = Path(__file__).resolve().parents[4] / "field_plans" / "range2017" / "plan.json"


def _client_when_up(url: str, timeout: float = 20.0) -> FoxgloveClient:
    deadline = time.monotonic() + timeout
    while True:
        try:
            return FoxgloveClient(url)
        except (OSError, InvalidHandshake, TimeoutError):
            if time.monotonic() > deadline:
                raise
            time.sleep(0.01)


def test_a_sil_run_is_seen_live_by_foxgloves_clients_as_it_is_logged(tmp_path):
    flight = flight_from_plan(PLAN, "pair2b")
    port = free_port(socket.SOCK_STREAM)
    url = f"ws://127.0.0.1:{port}"
    log = tmp_path / "pair2b.mcap"
    watcher = watch_with_typescript(url)  # retries until the server is up
    outcome: dict = {}

    def run() -> None:
        try:
            outcome["result"] = fly(flight, log_path=log, speedup=60.0, live=("127.0.0.1", port))
        except BaseException as exc:  # reported by the test, not lost in the thread
            outcome["error"] = exc

    flying = threading.Thread(target=run, name="sil-run")
    flying.start()
    try:
        client = _client_when_up(url)
    finally:
        flying.join(timeout=300)
    client.close()
    assert "error" not in outcome, outcome.get("error")
    ts = typescript_report(watcher)
    logged = foxglove_channels(log)
    assert client.ws.subprotocol == SUBPROTOCOL and ts["subprotocol"] == SUBPROTOCOL

    # the advertised channels: the log's Foxglove channels under the same schemas, and the run's status
    live = client.topics
    for topic, channel in logged.items():
        assert live[topic]["schemaName"] == channel.schema_name and live[topic]["encoding"] == "protobuf"
        assert ts["channels"][topic]["schemaName"] == channel.schema_name
    assert {"/status/autonomy", "/status/bridge", "/status/live_view"} <= set(live) & set(ts["channels"])
    assert live["/status/bridge"]["encoding"] == "json"

    # the fixes: each one shown live is one the log holds, at the same time, thinned to a screen's rate over the
    # whole run
    log_fixes: dict = {}  # a stamp is the bridge's receive time: reports read in one go share it
    for f in logged[foxglove.FIX_TOPIC].messages:
        log_fixes.setdefault((f["timestamp"]["sec"], f["timestamp"]["nsec"]), []).append(f)
    seen = client.received(foxglove.FIX_TOPIC)
    assert len(seen) > 50
    for fix in seen:
        assert fix in log_fixes[(fix["timestamp"]["sec"], fix["timestamp"]["nsec"])]
    stamps = sorted(log_fixes)
    shown = sorted((f["timestamp"]["sec"], f["timestamp"]["nsec"]) for f in seen)
    assert stamps.index(shown[0]) < 0.1 * len(stamps) and stamps.index(shown[-1]) > 0.9 * len(stamps)
    ts_last = ts["last"][foxglove.FIX_TOPIC]
    stamp = (ts_last["timestamp"]["seconds"], ts_last["timestamp"]["nanos"])
    assert (ts_last["latitude"], ts_last["longitude"]) in [(f["latitude"], f["longitude"]) for f in log_fixes[stamp]]
    assert ts["channels"][foxglove.FIX_TOPIC]["messages"] > 50

    # the scenario map with the predicted track, as the log has it
    [logged_map] = logged["/map/scenario"].messages
    assert "/map/scenario" in ts["last"], ts["statuses"]
    for doc in (client.received("/map/scenario")[-1], ts["last"]["/map/scenario"]):
        assert json.loads(doc["geojson"]) == json.loads(logged_map["geojson"])
    kinds = {f["properties"]["kind"] for f in json.loads(logged_map["geojson"])["features"]}
    assert "predicted_track" in kinds

    # the run's events and its status as they came
    events = [m["message"] for m in client.received(foxglove.LOG_TOPIC)]
    assert any(e.startswith("goal: ") for e in events)
    bridge = [m for t, _, m in read_log(log) if t == keys.status("uuv1", "bridge")]
    assert client.received("/status/bridge")[-1]["started_ns"] == bridge[-1]["started_ns"]
    own = client.received("/status/live_view")[-1]
    assert own["errors"] == 0 and own["sent"] > len(seen)
