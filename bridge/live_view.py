"""The run live in Foxglove: a WebSocket server of Foxglove's SDK, fed from one vehicle's bus.

A Foxglove app (or any client of the ``foxglove.sdk.v1`` subprotocol) connected to it sees
what the log will hold, as it happens: the same Foxglove channels the logger writes
(:mod:`bridge.foxglove`: the vehicle's fix, its local frame and trail, the scenario map with
the predicted track, the log of STATUSTEXT, bring-up, watchdog and referee events), and each
process's ``status/<name>`` as a JSON channel ``/status/<name>`` a Plot panel can draw (the
bridge's and the logger's counters, the watchdog's state, the back-seat's decision latency),
beside the view's own counters on ``/status/live_view``.

It is fed off the control path. It subscribes to the few keys it shows, never to
``mavlink/raw``, into Zenoh's own ring buffers: no Python runs on the bus's thread, and a
telemetry message or a back-seat status arriving faster than a screen needs is replaced
there, in the bus's own code, by the next (a vehicle at 20,000 frames/s costs the view
nothing it reads). One thread of its own takes what the rings hold :data:`TELEMETRY_HZ`
times a second, derives, encodes and hands messages to the SDK, which drops a slow client's
oldest messages rather than wait. STATUSTEXT, the bring-up's, watchdog's and referee's events
and the maps are kept in order in rings of their own. A client that connects, disconnects or
subscribes to everything therefore holds up nothing that commands the vehicle. A channel's
latest map, trail or status is sent again when a client subscribes to it, and the maps
every :data:`MAP_EVERY_S` as well, so a client that connects late still sees the scenario.
The scenario's map reaches a view that is up when it is put on the bus (a logger's arrival
puts it; see :class:`planner.fly.scenario_map.ScenarioMap`); the process that made it may
also hand it over with :meth:`LiveView.show_map`.

The protocol has no authentication: anyone who reaches the port sees the run. The server
binds to loopback unless a host is given.
"""

from __future__ import annotations

import collections
import json
import logging
import threading
import time
from typing import Any

import foxglove as sdk
import zenoh
from foxglove.websocket import ServerListener

from rapt.errors import InputError

from . import foxglove, keys
from .service import Service
from .session import undeclare, use_session

__all__ = ["LiveView", "parse_address", "DEFAULT_PORT", "STATUS_PREFIX", "OWN_STATUS"]

log = logging.getLogger(__name__)

#: Foxglove's usual WebSocket port.
DEFAULT_PORT = 8765
#: ``status/<name>`` on the bus is ``/status/<name>`` in the live view.
STATUS_PREFIX = "/status/"
#: The live view's own counters.
OWN_STATUS = "/status/live_view"
#: The telemetry the Foxglove channels are derived from (bridge.foxglove): its latest is what is shown.
TELEMETRY = ("GLOBAL_POSITION_INT", "ATTITUDE", "LOCAL_POSITION_NED")
#: How often a second the view takes the latest telemetry and statuses (a screen needs no more).
TELEMETRY_HZ = 50.0
#: Samples each ring of events (and of statuses) holds between two takes; beyond it the oldest goes.
EVENT_RING, STATUS_RING = 1024, 64
#: The processes whose every status is an event (bring-up steps, watchdog rulings, the referee's end).
EVENT_SOURCES = (keys.BRINGUP_SOURCE, keys.WATCHDOG_SOURCE, "referee")
#: The scenario's maps are sent again this often (s), whoever subscribed when.
MAP_EVERY_S = 2.0
#: How long after a subscription its topic's latest message is sent again.
RESEND_AFTER_S = 0.2
#: Topics whose last message is sent again to a client that subscribes late (they change rarely or state a state).
RESENT = ("/map/", foxglove.TRAIL_TOPIC, STATUS_PREFIX)
#: The Foxglove channels advertised from the start, so a client subscribes before the vehicle's first report.
ADVERTISED = (
    (foxglove.FIX_TOPIC, "foxglove.LocationFix"),
    (foxglove.LOG_TOPIC, "foxglove.Log"),
    (foxglove.TF_TOPIC, "foxglove.FrameTransform"),
    (foxglove.TRAIL_TOPIC, "foxglove.PosesInFrame"),
)


def parse_address(text: str, option: str = "--foxglove") -> tuple[str, int]:
    """``[HOST:]PORT`` -> (host, port); host 127.0.0.1 when only a port is given."""
    host, _, port = str(text).rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise InputError(f"{option}: expected [HOST:]PORT with a port 0-65535, got {text!r}")
    return (host.strip("[]") or "127.0.0.1"), number


def _json_schema(value: Any) -> dict:
    """A JSON Schema of ``value``'s shape, so Foxglove's panels can offer its fields."""
    if isinstance(value, bool):
        return {"type": "boolean"}
    if isinstance(value, (int, float)):
        return {"type": "number"}
    if isinstance(value, str):
        return {"type": "string"}
    if isinstance(value, dict):
        return {"type": "object", "properties": {str(k): _json_schema(v) for k, v in value.items()}}
    if isinstance(value, list):
        return {"type": "array", "items": _json_schema(value[0]) if value else {}}
    return {}


class _Listener(ServerListener):
    """The server's callbacks: a subscription asks the feeding thread to send a resent topic again."""

    def __init__(self, view: LiveView):
        self._view = view

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._view._subscribed(channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass


class LiveView(Service):
    """A Foxglove WebSocket server on ``host:port`` showing vehicle ``vehicle``'s bus (see the module docstring).

    ``session``: an open ``zenoh.Session`` (left open), a ``zenoh.Config``, or None for an
    in-process session. ``port`` 0 takes a free port (:attr:`port` tells which). A port in use
    raises :class:`~rapt.errors.InputError` naming it. ``maps``: GeoJSON documents by name, shown
    from the start as ``/map/<name>`` (see :meth:`show_map`).
    """

    _what = "live view"

    def __init__(
        self,
        session: zenoh.Session | zenoh.Config | None = None,
        *,
        vehicle: str = keys.DEFAULT_VEHICLE,
        host: str = "127.0.0.1",
        port: int = DEFAULT_PORT,
        name: str = "rapt",
        maps: dict[str, dict] | None = None,
    ):
        super().__init__()
        keys.everything(vehicle)  # validates the name
        self.vehicle, self.host, self.name = vehicle, host, name
        self.port = int(port)
        self._maps = dict(maps or {})
        self._session_arg = session
        self._session: zenoh.Session | None = None
        self._owns_session = False
        self._queue: collections.deque = collections.deque()  # maps handed over by show_map
        self._wake = threading.Event()
        self._context = sdk.Context()
        self._server: Any = None
        self._channels: dict[str, Any] = {}
        self._last: dict[str, tuple[bytes, int]] = {}  # resent topics' last message and time
        self._messages = foxglove.FoxgloveMessages()
        self._counts = dict.fromkeys(("received", "sent", "errors", "resent"), 0)
        #: kept in order: the vehicle's messages, the autonomy's events (each one matters), the maps
        self._event_keys = {keys.status(vehicle, n) for n in EVENT_SOURCES}
        self._latest: list[Any] = []  # one ring of 1 per telemetry message
        self._events: list[Any] = []
        self._statuses: Any = None
        self._resend_at: collections.deque = collections.deque()  # (monotonic time, topic) of late subscriptions

    # ----------------------------------------------------------------- life cycle
    def _open(self) -> None:
        # the channels known now exist before the server: a client connecting at once sees them complete
        for topic, schema_name in ADVERTISED:
            self._foxglove_channel(topic, schema_name)
        for map_name, document in self._maps.items():
            self._foxglove_channel(foxglove.map_topic(map_name), "foxglove.GeoJSON")
            self.show_map(map_name, document)
        try:
            self._server = sdk.start_server(
                name=self.name,
                host=self.host,
                port=self.port,
                context=self._context,
                server_listener=_Listener(self),
            )
        except RuntimeError as exc:
            if "in use" in str(exc):
                raise InputError(
                    f"--foxglove: port {self.port} on {self.host} is in use; give another port or stop what holds it"
                ) from None
            raise InputError(f"--foxglove: cannot serve on {self.host}:{self.port}: {exc}") from None
        self.port = int(self._server.port)
        self._session, self._owns_session = use_session(self._session_arg)
        v, ring, sub = self.vehicle, zenoh.handlers.RingChannel, self._session.declare_subscriber
        self._latest = [sub(keys.telemetry(v, m), ring(1)) for m in TELEMETRY]
        events = [keys.telemetry(v, "STATUSTEXT"), keys.map_document(v, "*"), *sorted(self._event_keys)]
        self._events = [sub(k, ring(EVENT_RING)) for k in events]
        self._statuses = sub(keys.status(v, "*"), ring(STATUS_RING))
        self._spawn("foxglove-live", self._feed)

    def _shutdown(self) -> None:
        self._wake.set()
        self._join(self._threads, timeout=5)  # before the rings go: the thread reads them
        undeclare(*self._latest, *self._events, self._statuses)
        if self._server is not None:
            self._server.stop()
        if self._owns_session and self._session is not None:
            self._session.close()

    @property
    def stats(self) -> dict[str, int]:
        """received (samples taken off the rings), sent (messages to the server), errors, resent (a latest map,
        trail or status sent again for a late subscriber), channels."""
        return {**self._counts, "channels": len(self._channels)}

    @property
    def url(self) -> str:
        """What to give Foxglove's "Open connection": ``ws://host:port``."""
        return f"ws://{self.host}:{self.port}"

    # ----------------------------------------------------------------- the feed
    def show_map(self, name: str, document: dict) -> None:
        """Show GeoJSON ``document`` as ``/map/<name>`` as if it had come on ``map/<name>`` (for the process that
        made it, when no logger's arrival has yet put it on the bus)."""
        self._queue.append((keys.map_document(self.vehicle, name), json.dumps(document, allow_nan=False).encode()))
        self._wake.set()

    def _subscribed(self, topic: str) -> None:
        """A client subscribed to ``topic``: send its latest again, once the subscription is in place (the
        server calls this before it is)."""
        self._resend_at.append((time.monotonic() + RESEND_AFTER_S, topic))
        self._wake.set()

    def _feed(self) -> None:
        """The one thread that reads the rings and talks to the server, :data:`TELEMETRY_HZ` times a second: the
        events in order, each status's latest, each telemetry message's latest; resends; its own status."""
        next_status = next_maps = time.monotonic()
        while not self._stop.is_set():
            self._wake.wait(timeout=1.0 / TELEMETRY_HZ)
            self._wake.clear()
            samples = [(k, p, True) for k, p in self._drain_queue()]
            for ring in self._events:
                samples += self._drain(ring)
            latest = {key: (key, payload, put) for key, payload, put in self._drain(self._statuses)}
            samples += [v for k, v in latest.items() if k not in self._event_keys]  # events came in order above
            for ring in self._latest:
                samples += self._drain(ring)
            for key, payload, put in samples:
                try:
                    self._counts["received"] += 1
                    self._take(key, payload, put)
                except Exception:  # one bad sample must not stop the view
                    self._counts["errors"] += 1
                    log.exception("live view: cannot show a sample on %s", key)
            while self._resend_at and self._resend_at[0][0] <= time.monotonic():
                self._resend(self._resend_at.popleft()[1])
            if time.monotonic() >= next_status:
                self._send_json(OWN_STATUS, self.stats, time.time_ns())
                next_status = time.monotonic() + 1.0
            if time.monotonic() >= next_maps:  # a map changes rarely and is small: every client has it soon
                for topic in [t for t in self._last if t.startswith("/map/")]:
                    self._resend(topic)
                next_maps = time.monotonic() + MAP_EVERY_S

    def _drain_queue(self) -> list[tuple[str, bytes]]:
        out = []
        while self._queue:
            out.append(self._queue.popleft())
        return out

    @staticmethod
    def _drain(ring: Any) -> list[tuple[str, bytes, bool]]:
        """What ``ring`` holds, oldest first (key, payload, put)."""
        out = []
        while (sample := ring.try_recv()) is not None:
            out.append((str(sample.key_expr), sample.payload.to_bytes(), sample.kind == zenoh.SampleKind.PUT))
        return out

    def _take(self, key: str, payload: bytes, put: bool) -> None:
        _, kind, name = keys.split(key)
        now = time.time_ns()
        if not put:
            obj: Any = {"type": "FeatureCollection", "features": []} if kind == "map" else {"deleted": True}
        else:
            try:
                obj = json.loads(payload)
            except ValueError:
                return
        if not isinstance(obj, dict):
            return
        stamp = obj.get("_recv_ns")
        ns = stamp if isinstance(stamp, int) and not isinstance(stamp, bool) else now
        if kind == "status":
            self._send_json(STATUS_PREFIX + name, obj, now)
        for topic, schema_name, message in self._messages.derive(kind, name, obj, ns):
            self._send_foxglove(topic, schema_name, foxglove.encode(schema_name, message), ns)

    def _channel(self, topic: str, make: Any) -> Any:
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._channels[topic] = make()
        return channel

    def _foxglove_channel(self, topic: str, schema_name: str) -> Any:
        schema = foxglove.schema(schema_name)
        return self._channel(
            topic,
            lambda: sdk.Channel(topic, schema=schema, message_encoding=foxglove.ENCODING, context=self._context),
        )

    def _send_foxglove(self, topic: str, schema_name: str, data: bytes, ns: int) -> None:
        self._send(self._foxglove_channel(topic, schema_name), topic, data, ns)

    def _send_json(self, topic: str, obj: dict, ns: int) -> None:
        channel = self._channel(topic, lambda: sdk.Channel(topic, schema=_json_schema(obj), context=self._context))
        self._send(channel, topic, json.dumps(obj).encode(), ns)

    def _send(self, channel: Any, topic: str, data: bytes, ns: int) -> None:
        if topic.startswith(RESENT) and topic != OWN_STATUS:
            self._last[topic] = (data, ns)
        channel.log(data, log_time=ns)
        self._counts["sent"] += 1

    def _resend(self, topic: str) -> None:
        last = self._last.get(topic)
        channel = self._channels.get(topic)
        if last is not None and channel is not None:
            channel.log(last[0], log_time=last[1])
            self._counts["resent"] += 1
