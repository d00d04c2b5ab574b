"""Loopback helpers shared by the tests that talk MAVLink and Zenoh: free ports, polling with a deadline."""

from __future__ import annotations

import contextlib
import socket
import threading
import time


def free_port(kind: int = socket.SOCK_STREAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, timeout: float = 5.0, what: str = "condition"):
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.005)


@contextlib.contextmanager
def no_new_threads(timeout: float = 5.0):
    """Assert that every thread started inside the block has ended (within ``timeout``) when it exits.

    Threads Python did not start are left out: a Rust runtime's thread (Zenoh's, Foxglove's) that
    calls back into Python appears as a "dummy thread", which Python never removes because it
    cannot see such a thread end (the threading docs) -- it is no thread of ours left running.
    """
    before = set(threading.enumerate())
    yield
    deadline = time.monotonic() + timeout
    alien = getattr(threading, "_DummyThread", ())

    def ours_left() -> list[str]:
        return [t.name for t in threading.enumerate() if t not in before and not isinstance(t, alien)]

    while (left := ours_left()) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not left, f"threads left running: {left}"
