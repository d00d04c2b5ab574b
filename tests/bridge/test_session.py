"""Undeclaring a Zenoh entity that another thread is still using (zenoh-python's "Already borrowed")."""

from __future__ import annotations

import logging
import threading
import time

import pytest
import zenoh

from bridge.session import open_session, undeclare


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
