"""The shared start/close life cycle, on a service of two threads that wait for the stop event."""

from __future__ import annotations

import pytest

from bridge.service import Service
from rapt.errors import RunError


class Waiter(Service):
    """Two threads that wait for the stop event; ``fail_after`` makes _open raise after that many."""

    _what = "waiter"

    def __init__(self, fail_after: int | None = None):
        super().__init__()
        self.fail_after = fail_after
        self.shutdowns = 0
        self.alive_at_shutdown: list[bool] = []

    def _open(self) -> None:
        for i in range(2):
            if self.fail_after == i:
                raise OSError("cannot open")
            self._spawn(f"waiter-{i}", self._stop.wait)

    def _shutdown(self) -> None:
        self.shutdowns += 1
        self._join(self._threads, timeout=5)
        self.alive_at_shutdown = [t.is_alive() for t in self._threads]


def test_start_spawns_named_daemon_threads_and_close_stops_them_once():
    with Waiter() as w:
        assert [t.name for t in w._threads] == ["waiter-0", "waiter-1"]
        assert all(t.daemon and t.is_alive() for t in w._threads) and not w.closed
    assert w.closed and w.shutdowns == 1 and w.alive_at_shutdown == [False, False]
    w.close()
    assert w.shutdowns == 1  # idempotent


def test_a_second_start_is_refused_and_names_the_service():
    w = Waiter().start()
    try:
        with pytest.raises(RunError, match="start: the waiter was already started"):
            w.start()
    finally:
        w.close()
    with pytest.raises(RuntimeError, match="already started"):
        w.start()  # nor after close


def test_a_failed_start_closes_what_it_opened_and_re_raises():
    w = Waiter(fail_after=1)
    with pytest.raises(OSError, match="cannot open"):
        w.start()
    assert w.closed and w.shutdowns == 1 and w.alive_at_shutdown == [False]


def test_close_without_start_shuts_down_once():
    w = Waiter()
    w.close()
    w.close()
    assert w.closed and w.shutdowns == 1 and w._threads == []
