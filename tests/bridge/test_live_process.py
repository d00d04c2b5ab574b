"""The live view in a process of its own: joined to the bus over loopback, it shows what the bus carries;
a port in use or a bad map is its one-line error in the parent; stopping it leaves no process behind."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest

from bridge import foxglove, keys
from bridge.frames import mavlink2, message_json
from bridge.live_process import LiveViewProcess
from bridge.session import open_session
from rapt.errors import InputError
from tests.support.foxglove_client import FoxgloveClient
from tests.support.loopback import free_port

NS = 1_795_790_247_083_170_978
M = mavlink2.MAVLink(None)
DOCUMENT = {
    "type": "FeatureCollection",
    "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [151.2, -33.8]}, "properties": {}}],
}


@pytest.fixture
def hub():
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    session = open_session(listen=[endpoint])
    yield session, endpoint
    session.close()


def test_the_child_joins_the_bus_and_a_client_sees_the_map_fixes_and_status(hub):
    session, endpoint = hub
    with LiveViewProcess(vehicle="uuv1", port=0, connect=[endpoint], maps={"scenario": DOCUMENT}) as view:
        assert os.sched_getscheduler(view.process.pid) == os.SCHED_IDLE  # it runs on CPU time nothing else wants
        pid = view.process.pid
        assert view.port > 0 and view.url == f"ws://127.0.0.1:{view.port}"
        with FoxgloveClient(view.url) as client:
            [doc] = client.wait_for(lambda: client.received("/map/scenario"), what="the map handed to the child")
            assert json.loads(doc["geojson"]) == DOCUMENT
            client.wait_for(lambda: client.subscribed(foxglove.FIX_TOPIC), what="a subscription to the fixes")

            def fix_shown():  # put again until shown: the child's subscription crosses the bus
                fix = M.global_position_int_encode(1, -338_512_345, 1_512_098_765, -2000, -2000, 0, 0, 0, 0)
                session.put(keys.telemetry("uuv1", "GLOBAL_POSITION_INT"), message_json(fix, NS))
                return client.received(foxglove.FIX_TOPIC)

            [fix, *_] = client.wait_for(fix_shown, what="a fix put on the hub's session")
            assert fix["latitude"] == pytest.approx(-33.8512345)
            session.put(keys.status("uuv1", "bridge"), json.dumps({"link_lost": 0, "forwarded": 12}))
            [status] = client.wait_for(lambda: client.received("/status/bridge"), what="the bridge's status")
            assert status == {"link_lost": 0, "forwarded": 12}
    with pytest.raises(ProcessLookupError):  # stopped and reaped
        os.kill(pid, 0)


def test_a_port_in_use_is_the_childs_one_line_error_in_the_parent(hub):
    _, endpoint = hub
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        view = LiveViewProcess(port=port, connect=[endpoint])
        with pytest.raises(InputError, match=rf"^--foxglove: port {port} on 127.0.0.1 is in use; give another port"):
            view.start()
        assert view.process is None


def test_a_bad_map_file_exits_2_with_one_line_naming_the_option(tmp_path, hub):
    _, endpoint = hub
    bad = tmp_path / "map.geojson"
    bad.write_text("{not json")
    done = subprocess.run(
        [sys.executable, "-m", "bridge.live_process", "--connect", endpoint, "--map", f"scenario={bad}"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2 and done.stdout == ""
    [line] = done.stderr.strip().splitlines()
    assert line.startswith(f"--map: cannot read GeoJSON {str(bad)!r}")
