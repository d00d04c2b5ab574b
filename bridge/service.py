"""Start once, close once: the life cycle of the bus's long-running parts (bridge, logger).

:class:`Service` owns what they all did by hand: the started/closed flags, a stop event,
named daemon threads, an idempotent :meth:`Service.close` that also cleans up after a failed
:meth:`Service.start`, and the context-manager protocol. A subclass says only what to open
(:meth:`Service._open`) and how to shut down (:meth:`Service._shutdown`), in its own order.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from typing import Any, Self

from rapt.errors import RunError

__all__ = ["Service"]


class Service:
    """Base of a part that runs threads between :meth:`start` and :meth:`close` (or a ``with`` block).

    ``start`` runs :meth:`_open` once (a second call raises :class:`~rapt.errors.RunError`); if ``_open``
    raises, ``close`` runs before the error propagates, so ``_shutdown`` must cope with a
    half-open service. ``close`` sets :attr:`_stop` and runs :meth:`_shutdown` exactly once,
    whether or not the service was started; later calls do nothing.
    """

    #: What the service is called in errors ("start: the bridge was already started").
    _what = "service"

    def __init__(self) -> None:
        self._stop = threading.Event()  # set by close(): loops waiting on it end
        self._threads: list[threading.Thread] = []  # spawned, in order
        self._started = False
        self._closed = False

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @property
    def closed(self) -> bool:
        """close() was called (the service may not be started again)."""
        return self._closed

    def start(self) -> Self:
        """Open everything and start the threads (:meth:`_open`); on failure close and re-raise."""
        if self._started:
            raise RunError(f"start: the {self._what} was already started")
        self._started = True
        try:
            self._open()
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Set the stop event, then shut down (:meth:`_shutdown`). Idempotent."""
        if self._closed:
            return
        self._closed = True
        self._stop.set()
        self._shutdown()

    def _spawn(self, name: str, target: Callable[..., Any], *args: Any) -> threading.Thread:
        """Start ``target(*args)`` on a daemon thread called ``name``, remembered in :attr:`_threads`."""
        thread = threading.Thread(target=target, args=args, name=name, daemon=True)
        thread.start()
        self._threads.append(thread)
        return thread

    @staticmethod
    def _join(threads: Iterable[threading.Thread], timeout: float) -> None:
        """Wait up to ``timeout`` seconds for each thread in turn (a thread stuck past it is left, as a daemon)."""
        for thread in threads:
            thread.join(timeout=timeout)

    def _open(self) -> None:
        """Acquire resources and :meth:`_spawn` threads; may raise after acquiring some."""
        raise NotImplementedError

    def _shutdown(self) -> None:
        """Stop the threads and release whatever :meth:`_open` acquired (possibly only part of it)."""
        raise NotImplementedError
