"""The hub's link for a live view: over it each telemetry key (and the autonomy's status) leaves at most at the
view's rate, while a process joined over TCP still gets every sample and events pass the view's link untouched."""

from __future__ import annotations

import os
import socket
import threading
import time
from collections import Counter

import pytest

from bridge import keys
from bridge.live_view import TELEMETRY, TELEMETRY_HZ
from bridge.session import open_session
from bridge.view_link import ViewLink
from tests.support.loopback import free_port

RATE_HZ, SECONDS = 500.0, 2.0


class Tally:
    """Samples a client session received, by key."""

    def __init__(self, session, vehicle: str):
        self.counts: Counter = Counter()
        self._lock = threading.Lock()
        self._subscriber = session.declare_subscriber(f"rapt/{vehicle}/**", self._on)

    def _on(self, sample) -> None:
        with self._lock:
            self.counts[str(sample.key_expr)] += 1


@pytest.fixture
def link():
    view = ViewLink("uuv1")
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    hub = open_session(listen=[endpoint], extend=view.add_to)
    clients = []
    try:
        yield hub, endpoint, view, clients
    finally:
        for c in clients:
            c.close()
        hub.close()
        view.close()
    assert not os.path.exists(view.endpoint.partition("/")[2])  # the socket's directory is gone


def test_the_view_link_thins_telemetry_to_the_screen_rate_and_nothing_else(link):
    hub, endpoint, view, clients = link
    tcp = open_session(connect=[endpoint])
    unix = open_session(connect=[view.endpoint])
    clients += [tcp, unix]
    everything, thinned = Tally(tcp, "uuv1"), Tally(unix, "uuv1")
    time.sleep(1.0)  # both subscriptions have reached the hub
    telemetry = [keys.telemetry("uuv1", m) for m in TELEMETRY] + [keys.status("uuv1", keys.DEFAULT_ACTIVE)]
    event = keys.telemetry("uuv1", "STATUSTEXT")
    n = int(RATE_HZ * SECONDS)
    start = time.monotonic()
    for k in range(n):
        for key in telemetry:
            hub.put(key, b"x" * 40)
        if k % 50 == 0:
            hub.put(event, b"event")
            hub.put(keys.status("uuv1", keys.BRINGUP_SOURCE), b"step")
        time.sleep(max(0.0, start + (k + 1) / RATE_HZ - time.monotonic()))
    elapsed = time.monotonic() - start
    time.sleep(1.0)
    for key in telemetry:
        assert everything.counts[key] == n, key  # TCP: every sample
        # the view's link: each key on its own at most the screen's rate, and about that many
        assert 0.5 * TELEMETRY_HZ * elapsed <= thinned.counts[key] <= TELEMETRY_HZ * elapsed + 5, key
    for key in (event, keys.status("uuv1", keys.BRINGUP_SOURCE)):  # events untouched
        assert thinned.counts[key] == everything.counts[key] == len(range(0, n, 50)), key


def test_a_config_file_s_mode_keyed_listen_list_gains_the_view_endpoint():
    import zenoh

    config = zenoh.Config.from_json5('{mode: "peer", listen: {endpoints: {peer: ["tcp/127.0.0.1:7447"]}}}')
    with ViewLink("uuv1") as view:
        view.add_to(config)
        assert f'"{view.endpoint}"' in config.get_json("listen/endpoints")
        assert '"rapt/uuv1/mavlink/ATTITUDE"' in config.get_json("downsampling")
