"""Undeclaring a Zenoh entity that another thread is still using (zenoh-python's "Already borrowed")."""

from __future__ import annotations

import json
import logging
import threading
import time

import pytest
import zenoh

from bridge.session import open_session, undeclare, zenoh_config
from rapt.errors import LinkError
from tests.support.loopback import free_port, wait_until


@pytest.fixture
def session():
    s = open_session()  # in-process: no endpoint
    yield s
    s.close()


def test_a_publisher_still_putting_in_another_thread_is_undeclared_once_its_puts_end(session):
    """A worker that outlived its join still publishes its last samples; undeclaring waits for them."""
    pub = session.declare_publisher("rapt/test/borrow")
    errors: list[str] = []
    putting = threading.Event()

    def last_burst() -> None:
        for _ in range(20_000):
            try:
                pub.put(b"x")
            except zenoh.ZError:
                return  # undeclared between two puts: the worker's own way out
            except RuntimeError as error:
                errors.append(str(error))
                return
            putting.set()

    worker = threading.Thread(target=last_burst)
    worker.start()
    assert putting.wait(5)
    undeclare(pub)  # mid-burst, a direct pub.undeclare() raises RuntimeError("Already borrowed")
    worker.join(10)
    assert not worker.is_alive() and errors == []
    with pytest.raises(zenoh.ZError):
        pub.put(b"after")


def test_an_entity_busy_past_the_patience_is_left_with_a_warning_not_an_error(session, caplog):
    sub = session.declare_subscriber("rapt/test/blocked")
    got: list = []
    worker = threading.Thread(target=lambda: got.append(sub.recv()))  # holds the subscriber until a sample comes
    worker.start()
    time.sleep(0.2)
    with caplog.at_level(logging.WARNING, logger="bridge.session"):
        undeclare(sub, patience_s=0.2)
    assert "still in use by another thread" in caplog.text
    session.put("rapt/test/blocked", b"release")
    worker.join(5)
    assert got and not worker.is_alive()
    undeclare(sub)  # free now: undeclared
    with pytest.raises(zenoh.ZError):
        sub.try_recv()


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
