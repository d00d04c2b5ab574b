"""The live view as a Foxglove client sees it: advertised channels, fixes, the map, status JSON, bad ports."""

from __future__ import annotations

import json
import socket
import time

import pytest

from bridge import foxglove, keys
from bridge.frames import mavlink2, message_json
from bridge.live_view import OWN_STATUS, TELEMETRY_HZ, LiveView, parse_address
from bridge.session import open_session
from rapt.errors import InputError
from tests.support.foxglove_client import SUBPROTOCOL, FoxgloveClient
from tests.support.loopback import free_port

NS = 1_795_790_247_083_170_978
M = mavlink2.MAVLink(None)
DOCUMENT = {
    "type": "FeatureCollection",
    "features": [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [151.2, -33.8]}, "properties": {}}],
}


@pytest.fixture
def bus():
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
    yield session
    session.close()


def test_a_client_gets_the_foxglove_channels_and_the_status_as_they_happen(bus):
    with LiveView(bus, vehicle="uuv1", port=0) as view:
        assert view.url == f"ws://127.0.0.1:{view.port}" and view.port > 0
        bus.put(keys.map_document("uuv1", "scenario"), json.dumps(DOCUMENT))
        with FoxgloveClient(view.url) as client:
            client.wait_for(lambda: client.server_info, what="serverInfo")
            assert SUBPROTOCOL == client.ws.subprotocol
            # the map was put before the client came: it is sent again when the client subscribes (and every
            # MAP_EVERY_S, so on a loaded machine a second copy may arrive with the first: each is the document)
            docs = client.wait_for(lambda: client.received("/map/scenario"), what="the scenario map")
            assert docs and all(json.loads(doc["geojson"]) == DOCUMENT for doc in docs)
            assert client.topics["/map/scenario"]["schemaName"] == "foxglove.GeoJSON"
            client.wait_for(lambda: client.subscribed(foxglove.FIX_TOPIC), what="a subscription to the fixes")
            time.sleep(0.2)  # the subscription on its way to the server
            for k in range(5):  # at a screen's rate: each shown
                fix = M.global_position_int_encode(k, -338_512_345 + k, 1_512_098_765, -2000, -2000, 0, 0, 0, 0)
                bus.put(keys.telemetry("uuv1", "GLOBAL_POSITION_INT"), message_json(fix, NS + k))
                time.sleep(1.5 / TELEMETRY_HZ)
            bus.put(keys.telemetry("uuv1", "STATUSTEXT"), message_json(M.statustext_encode(3, b"Leak!"), NS))
            bus.put(keys.status("uuv1", "watchdog"), json.dumps({"event": "intervention", "reason": "collision"}))
            bus.put(keys.status("uuv1", "bridge"), json.dumps({"link_lost": 0, "forwarded": 12}))
            fixes = client.wait_for(
                lambda: len(client.received(foxglove.FIX_TOPIC)) >= 5 and client.received(foxglove.FIX_TOPIC),
                what="five fixes",
            )
            assert [f["latitude"] for f in fixes] == pytest.approx([(-338_512_345 + k) / 1e7 for k in range(5)])
            assert fixes[0]["timestamp"] == {"sec": NS // 10**9, "nsec": NS % 10**9}
            lines = client.wait_for(
                lambda: len(client.received(foxglove.LOG_TOPIC)) >= 2 and client.received(foxglove.LOG_TOPIC),
                what="two log lines",
            )
            assert {(m["level"], m["message"].split(":")[0]) for m in lines} == {
                (foxglove.ERROR, "Leak!"),
                (foxglove.ERROR, "intervention"),
            }
            [bridge] = client.wait_for(lambda: client.received("/status/bridge"), what="the bridge's status")
            assert bridge == {"link_lost": 0, "forwarded": 12}
            assert client.topics["/status/bridge"]["encoding"] == "json"
            assert json.loads(client.topics["/status/bridge"]["schema"])["properties"]["forwarded"] == {
                "type": "number"
            }
            before = len(client.received(foxglove.FIX_TOPIC))
            for k in range(200):  # far faster than a screen: the latest is shown, not every one
                fix = M.global_position_int_encode(k, 0, 0, -2000, -2000, 0, 0, 0, 0)
                bus.put(keys.telemetry("uuv1", "GLOBAL_POSITION_INT"), message_json(fix, NS))
            last = client.wait_for(
                lambda: [f for f in client.received(foxglove.FIX_TOPIC)[before:] if f["latitude"] == 0.0],
                what="the burst's fixes",
            )
            time.sleep(0.2)
            assert 1 <= len(client.received(foxglove.FIX_TOPIC)) - before < 50 and last
            own = client.wait_for(lambda: client.received(OWN_STATUS), what="the view's own status")
            assert own[-1]["errors"] == 0
        assert view.stats["errors"] == 0 and view.stats["sent"] > 0


def test_a_port_in_use_is_one_line_naming_it(bus):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        view = LiveView(bus, port=port)
        with pytest.raises(InputError, match=rf"--foxglove: port {port} on 127.0.0.1 is in use"):
            view.start()
        assert view.closed


@pytest.mark.parametrize(
    "text, expected",
    [("8765", ("127.0.0.1", 8765)), ("0.0.0.0:9000", ("0.0.0.0", 9000)), ("[::1]:9001", ("::1", 9001))],
)
def test_address_is_host_and_port_with_loopback_by_default(text, expected):
    assert parse_address(text) == expected


@pytest.mark.parametrize("text", ["", "http", "host:", "70000", "a:b"])
def test_a_bad_address_names_the_option(text):
    with pytest.raises(InputError, match=r"--foxglove: expected \[HOST:\]PORT"):
        parse_address(text)
