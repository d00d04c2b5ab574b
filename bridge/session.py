"""Zenoh sessions that stay on loopback unless a deployment config file says otherwise.

Zenoh 1.x peers listen on every interface and multicast-scout by default; a test rig or a
single-computer vehicle must not. :func:`zenoh_config` turns scouting (multicast and gossip)
off and uses only the endpoints given, which must be loopback (``tcp/127.0.0.1:7447``,
``tcp/[::1]:7447``, ``tcp/localhost:7447`` or ``unixsock-stream/<path>``).

Topology: one process (normally the one running the bridge) listens on a hub endpoint as a
peer; every other process connects to it in client mode. A peer routes for its clients, but
peers do not forward between other peers, so two back-seats connected to the hub as peers
would not hear each other (probed on eclipse-zenoh 1.10). A config file (a real deployment
with a back-seat on another computer) is taken as-is.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

import zenoh

from rapt.errors import InputError, LinkError, MissingFileError

__all__ = [
    "DEFAULT_HUB",
    "CONNECT_TIMEOUT_S",
    "zenoh_config",
    "open_session",
    "use_session",
    "undeclare",
]

#: The conventional hub endpoint when nothing else is given to a command line.
DEFAULT_HUB = "tcp/127.0.0.1:7447"
#: How long :func:`undeclare` waits for another thread's call on an entity to end.
UNDECLARE_PATIENCE_S = 5.0

log = logging.getLogger(__name__)

#: How long a client waits for its hub by default. Processes of one vehicle start in any
#: order (a systemd unit, a launch script, a test); Zenoh's client default (0) fails at once.
CONNECT_TIMEOUT_S = 30.0

_LOOPBACK_HOSTS = ("127.", "[::1]", "localhost")


def _endpoints(values: Iterable[str] | str, argument: str) -> list[str]:
    if isinstance(values, str):
        values = [values]
    out = []
    for endpoint in values:
        if not isinstance(endpoint, str) or "/" not in endpoint:
            raise InputError(f"{argument}: {endpoint!r} is not a Zenoh endpoint like 'tcp/127.0.0.1:7447'")
        protocol, _, address = endpoint.partition("/")
        if protocol == "unixsock-stream":
            out.append(endpoint)
            continue
        host = address.split("#", 1)[0].split("?", 1)[0]
        if protocol not in ("tcp", "udp", "tls", "quic", "ws") or not host.startswith(_LOOPBACK_HOSTS):
            raise InputError(
                f"{argument}: {endpoint!r} is not a loopback endpoint; pass config_file for other networks"
            )
        out.append(endpoint)
    return out


def zenoh_config(
    listen: Iterable[str] | str = (),
    connect: Iterable[str] | str = (),
    config_file: str | Path | None = None,
    *,
    mode: str | None = None,
    connect_timeout: float = CONNECT_TIMEOUT_S,
) -> zenoh.Config:
    """A config listening on ``listen`` and connecting to ``connect``, scouting off.

    ``mode`` defaults to ``"client"`` when only ``connect`` is given and ``"peer"`` otherwise
    (a hub, or with neither endpoint an in-process-only session). With ``config_file`` the
    file is loaded unchanged and the other arguments must be left out. A client retries its
    endpoints for ``connect_timeout`` seconds before giving up, so it may start before its hub.
    """
    if config_file is not None:
        if listen or connect or mode:
            raise InputError("config_file: give either a config file or listen/connect/mode, not both")
        path = Path(config_file)
        if not path.is_file():
            raise MissingFileError(f"config_file: {str(path)!r} does not exist")
        return zenoh.Config.from_file(str(path))
    listen, connect = _endpoints(listen, "listen"), _endpoints(connect, "connect")
    if mode is None:
        mode = "client" if connect and not listen else "peer"
    if mode not in ("peer", "client", "router"):
        raise InputError(f"mode: expected 'peer', 'client' or 'router', got {mode!r}")
    if mode == "client" and (listen or not connect):
        raise InputError("mode: a client needs connect endpoints and cannot listen")
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(connect))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    if mode == "client":
        if not connect_timeout > 0:
            raise InputError(f"connect_timeout: expected a positive number of seconds, got {connect_timeout!r}")
        config.insert_json5("connect/timeout_ms", json.dumps(int(connect_timeout * 1000)))
        config.insert_json5(
            "connect/retry", json.dumps({"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2})
        )
    return config


def open_session(
    listen: Iterable[str] | str = (),
    connect: Iterable[str] | str = (),
    config_file: str | Path | None = None,
    *,
    mode: str | None = None,
    connect_timeout: float = CONNECT_TIMEOUT_S,
    extend: Callable[[zenoh.Config], Any] | None = None,
) -> zenoh.Session:
    """Open a session with :func:`zenoh_config` (the same arguments); close it when done.

    ``extend`` changes the config before it opens (:meth:`bridge.view_link.ViewLink.add_to` adds a live view's link).

    Raises :class:`~rapt.errors.LinkError` (a ``ConnectionError``) naming the endpoints when no hub answered in time.
    """
    connect = [connect] if isinstance(connect, str) else list(connect)
    config = zenoh_config(listen, connect, config_file, mode=mode, connect_timeout=connect_timeout)
    if extend is not None:
        extend(config)
    try:
        return zenoh.open(config)
    except zenoh.ZError as exc:
        where = ", ".join(connect)
        raise LinkError(
            f"zenoh: could not open the session ({where or 'config file'}): {str(exc).split(' at ')[0]}; "
            "start the hub (rapt-plan bridge) first or fix the endpoint"
        ) from exc


def use_session(session: zenoh.Session | zenoh.Config | None) -> tuple[zenoh.Session, bool]:
    """The session a bus part runs on, and whether it owns it (opened it here, so must close it).

    An open ``zenoh.Session`` is used as it is and left to its owner; a ``zenoh.Config`` is
    opened; None opens :func:`zenoh_config`'s in-process-only session.
    """
    if isinstance(session, zenoh.Session):
        return session, False
    return zenoh.open(session if session is not None else zenoh_config()), True


def receive(subscriber: Any) -> Iterator[Any]:
    """The samples of a channel subscriber as they arrive, blocking, until it is undeclared.

    A reader thread iterates this rather than polling ``try_recv`` (which keeps a core busy
    waking up on an idle bus); its owner undeclares the subscriber to end the iteration.
    """
    handler = subscriber.handler
    while True:
        try:
            yield handler.recv()
        except zenoh.ZError:  # undeclared (or its session closed): the reader is done
            return


def undeclare(*entities: Any, patience_s: float = UNDECLARE_PATIENCE_S) -> None:
    """Undeclare each publisher, subscriber or token given, skipping None and those already gone.

    zenoh-python refuses to undeclare an entity while another thread is inside one of its
    calls (a ``put`` still running in a worker that outlived its join, a ``try_recv``): the
    binding raises ``RuntimeError("Already borrowed")``. That call ends soon, so undeclaring
    is retried for up to ``patience_s``; an entity still busy then is left to its session's
    close, with a warning, rather than turning a finished run into an error.
    """
    for entity in entities:
        if entity is None:
            continue
        deadline = time.monotonic() + patience_s
        while True:
            try:
                entity.undeclare()
            except zenoh.ZError:
                pass  # already undeclared, or its session closed
            except RuntimeError as error:
                if "borrow" not in str(error).lower():
                    raise
                if time.monotonic() < deadline:
                    time.sleep(0.002)
                    continue
                log.warning(
                    "zenoh: %r still in use by another thread after %.1f s; left to its session", entity, patience_s
                )
            break
