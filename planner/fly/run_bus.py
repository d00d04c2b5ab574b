"""The Zenoh sessions of one run's parts: one loopback session, or one per role on the range's secure bus.

Without keys every part of ``rapt-plan run`` shares one peer session on a free loopback
port, as it always has. With the range's keys (``rapt-plan bus-keys``, :mod:`bridge.range_keys`)
the bridge role's session is the hub (it listens on the hub endpoint with mutual TLS and the
access rules of :mod:`bridge.access`) and the parts that are processes of their own on a range
(``rapt-plan autonomy``, ``log``, the watchdog, the operator's control) join it as clients, each
as its role (:data:`PART_ROLES`), so a run goes through the same checks the range's bus makes.

The parts that exist only inside ``rapt-plan run`` share the bridge's session: the virtual range
(it adds frames to ``mavlink/raw`` as if the vehicle had sent them), the bring-up (it arms the
vehicle and switches its modes through the bridge object itself), the referee and the run's
metadata. They live in the process that holds the hub's key and the bridge, so a client
role would give them no less than they already hold.

Parts on different sessions see each other's declarations only once these have crossed the hub,
so a run waits for them (:meth:`RunBus.wait_for_parts`, :func:`put_when_heard`) rather than lose
its first samples.
"""

from __future__ import annotations

import json
import socket
import time
from pathlib import Path
from typing import Any

import zenoh

from bridge import keys
from bridge.session import open_session
from bridge.view_link import ViewLink
from planner.fly.lifecycle import wait_for
from rapt.errors import LinkError, LinkTimeoutError

__all__ = ["PART_ROLES", "RunBus", "free_port", "put_when_heard", "put_roles_of"]

#: The role each in-process part of a run joins the secure bus as (an autonomy's role is its source name).
PART_ROLES = {
    "bridge": "bridge",
    "virtual_range": "bridge",
    "bringup": "bridge",
    "referee": "bridge",
    "scenario_meta": "bridge",
    "scenario_map": keys.DEFAULT_ACTIVE,
    "backseat": keys.DEFAULT_ACTIVE,
    "recorder": keys.DEFAULT_ACTIVE,
    "watchdog": keys.WATCHDOG_SOURCE,
    "control": "operator",
    "logger": "logger",
    "live_view": "logger",  # it only reads, as the logger does
}

#: How long a part's declarations may take to cross the hub.
HEARD_TIMEOUT_S = 10.0


def free_port(kind: int = socket.SOCK_DGRAM) -> int:
    """A free loopback port (UDP by default)."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class RunBus:
    """The sessions of one run: :meth:`session` of a role, the bridge's first (it is the hub).

    ``keys_dir`` None: one loopback peer session serves every role. Otherwise each role's
    session comes from ``role_config(keys_dir, role)``, which checks its certificate and key
    first (a one-line error naming the file and the fix, before anything joins the bus).
    """

    def __init__(
        self, keys_dir: str | Path | None = None, *, vehicle: str = keys.DEFAULT_VEHICLE, roles: tuple[str, ...] = ()
    ):
        self.keys_dir = None if keys_dir is None else Path(keys_dir)
        self.vehicle = vehicle
        self._sessions: dict[str, Any] = {}
        self._shared: Any = None
        #: the loopback bus's endpoint, where a part in a process of its own connects (None on the secure bus)
        self.endpoint: str | None = None
        #: the loopback bus's link for a live view, its telemetry thinned to a screen's rate (None on the secure bus)
        self._view_link: ViewLink | None = None
        if self.keys_dir is None:
            self.endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
            self._view_link = ViewLink(vehicle)
            try:
                self._shared = open_session(listen=[self.endpoint], extend=self._view_link.add_to)
            except BaseException:
                self._view_link.close()
                raise
            return
        from bridge.range_keys import role_config

        self._role_config = role_config
        for role in ("bridge", *roles):  # every key checked before anything joins: a bad one stops the run at once
            role_config(self.keys_dir, role)
        self._open_role("bridge")

    @property
    def secure(self) -> bool:
        """Whether the parts join the range's secure bus, each as its role."""
        return self.keys_dir is not None

    def joined_as(self, role: str) -> dict[str, Any]:
        """How a part in a process of its own joins this bus as ``role``: ``{"connect": [endpoint]}`` on the
        loopback bus, ``{"keys_dir": DIR, "role": role}`` on the secure one."""
        if self.keys_dir is None:
            return {"connect": [self.endpoint]}
        return {"keys_dir": self.keys_dir, "role": role}

    def view_joined(self) -> dict[str, Any]:
        """How a live view joins this bus: over the hub's view link on the loopback bus
        (:mod:`bridge.view_link`), as the live view's role on the secure one."""
        if self._view_link is None:
            return self.joined_as(PART_ROLES["live_view"])
        return {"connect": [self._view_link.endpoint]}

    def put_roles(self) -> dict[str, list[str]] | None:
        """``{key expression: [roles allowed to put it]}`` from the hub's own config, for the logger
        (:mod:`bridge.channel_roles`); None on the loopback bus."""
        return None if self.keys_dir is None else put_roles_of(self.keys_dir, self.vehicle)

    def session(self, role: str) -> Any:
        """The session of ``role`` (opened on first use)."""
        if self._shared is not None:
            return self._shared
        return self._sessions.get(role) or self._open_role(role)

    def _open_role(self, role: str) -> Any:
        assert self.keys_dir is not None
        config = self._role_config(self.keys_dir, role)
        try:
            session = zenoh.open(config)
        except zenoh.ZError as exc:
            raise LinkError(
                f"{self.keys_dir / (role + '.json5')}: role {role!r} could not join the bus: "
                f"{str(exc).split(' at ')[0]}; is the hub (the bridge role) up, and its endpoint free?"
            ) from exc
        self._sessions[role] = session
        return session

    def put(self, role: str, key: str, payload: str, *, when_heard: bool = False) -> None:
        """Put ``payload`` on ``key`` from ``role``'s session; ``when_heard``: once a subscriber of it is known
        (a client of the hub learns of the hub's subscribers over the network, :func:`put_when_heard`)."""
        if when_heard:
            put_when_heard(self.session(role), key, payload)
        else:
            self.session(role).put(key, payload)

    def wait_for_parts(self, *names: str, timeout_s: float = HEARD_TIMEOUT_S) -> None:
        """Wait until the hub holds the liveliness tokens ``alive/<name>`` of the parts named: their
        subscriptions, declared before their tokens on the same link, are known to the hub then."""
        hub = self.session("bridge")
        wanted = {keys.alive(self.vehicle, name) for name in names}

        def heard() -> bool:
            seen = {str(reply.ok.key_expr) for reply in hub.liveliness().get(keys.alive(self.vehicle, "*")) if reply.ok}
            return wanted <= seen

        if not wait_for(heard, timeout_s, poll_s=0.02):
            raise LinkTimeoutError(
                f"bus: the hub did not hear {', '.join(sorted(names))} within {timeout_s:g} s; "
                "check that each role may declare its liveliness token"
            )

    def close(self) -> None:
        """Close every session, the hub's last."""
        if self._shared is not None:
            self._shared.close()
            if self._view_link is not None:
                self._view_link.close()
            return
        for role, session in reversed(list(self._sessions.items())):
            if role != "bridge":
                session.close()
        if "bridge" in self._sessions:
            self._sessions["bridge"].close()
        self._sessions.clear()

    def __enter__(self) -> RunBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def put_when_heard(session: Any, key: str, payload: str | bytes, timeout_s: float = HEARD_TIMEOUT_S) -> bool:
    """Put ``payload`` on ``key`` once a subscriber of it is known to ``session`` (a client learns of
    the hub's subscribers over the network); whether one was heard in ``timeout_s`` (it is put anyway)."""
    pub = session.declare_publisher(key)
    try:
        heard = wait_for(lambda: pub.matching_status.matching, timeout_s, poll_s=0.005)
        pub.put(payload)
        time.sleep(0)  # let the put leave before the publisher goes
        return heard
    finally:
        pub.undeclare()


def put_roles_of(keys_dir: str | Path, vehicle: str) -> dict[str, list[str]]:
    """``{key expression: [roles allowed to put it]}`` for a logger with the keys ``keys_dir``: from the
    hub's own rules when ``bridge.json5`` is there, else rebuilt from the roles present (every autonomy
    of the range is then named only if its files were copied too)."""
    from bridge.access import HUB_ROLE, OTHER_ROLES, access_rules
    from bridge.channel_roles import put_roles
    from bridge.range_keys import role_names

    hub_config = Path(keys_dir) / f"{HUB_ROLE}.json5"
    if hub_config.is_file():
        try:
            return put_roles(json.loads(zenoh.Config.from_file(str(hub_config)).get_json("access_control")))
        except (zenoh.ZError, ValueError):
            pass  # not a config of ours: the roles present say it
    autonomies = [r for r in role_names(keys_dir) if r not in (HUB_ROLE, *OTHER_ROLES)]
    return put_roles(access_rules(vehicle, autonomies or [keys.DEFAULT_ACTIVE]))
