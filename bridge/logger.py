"""Everything on one vehicle's bus, recorded to an MCAP file that Foxglove opens and a crash cannot ruin.

Each key becomes a JSON channel (``jsonschema`` schemas), raw MAVLink frames go to
``/mavlink/raw`` with their signature blocks stripped (logs must never carry signatures),
``meta/*`` keys also become MCAP metadata records, and liveliness changes are logged as
``{"alive": bool}`` on the token's key. Chunks are small and flushed about once a second,
so a logger killed with SIGKILL leaves a file that :func:`read_log` reads up to the last
flush. The writer thread takes samples straight off a deep Zenoh channel (about a minute of
20,000 frames/s; a slow disk holds up the bus instead of Zenoh dropping). Anything that
cannot be written is counted in ``stats["errors"]``, never dropped silently.

Losses are counted and reported (:mod:`bridge.loss`): publications of the bridge that never
arrived, from the numbers in their attachments (``bus_lost``); the MAVLink frames the
bridge's senders lost, from the bridge's ``status/bridge`` (``link_lost``); write errors. The
logger publishes its counters on ``status/logger`` once a second, and writes them at finish
as the metadata record ``rapt.losses`` (:data:`LOSSES_METADATA`, see :meth:`McapLogger.losses`).

Beside those channels, Foxglove's well-known messages derived from them (:mod:`bridge.foxglove`:
the vehicle's position fix, a log of STATUSTEXT and the autonomy's events, the local frame)
are written so Foxglove's Map, Log and 3D panels show the run without configuration; a
``map/<name>`` GeoJSON document is written only as its ``foxglove.GeoJSON`` channel. They are
counted in ``stats["derived"]``, apart from ``written``. A map's publisher puts it again
whenever a logger's liveliness token appears (:class:`planner.fly.scenario_map.ScenarioMap`), so a
logger started after the planner still records it.

On the range's secure bus (:mod:`bridge.range_keys`) a logger given the hub's rules (``roles``,
:func:`bridge.channel_roles.put_roles`) records which role each channel came from: the channel
metadata ``rapt.role`` (``"autonomy"``, ``"operator,watchdog"``: the roles allowed to put it;
``"bridge"``: the hub's own), and the metadata record ``rapt.roles`` (:data:`ROLES_METADATA`)
mapping the rules' key expressions to roles.

Payloads that are not a JSON object are wrapped: ``{"value": <JSON or text>}``, or
``{"base64": ...}`` for bytes that are not UTF-8.
"""

from __future__ import annotations

import argparse
import base64
import collections
import functools
import json
import logging
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import zenoh
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import CompressionType, Writer

from rapt.errors import InputError

from . import foxglove, keys
from .channel_roles import HUB, ChannelRoles
from .frames import strip_signature
from .loss import PublicationGaps
from .mcap_channels import McapChannels, Schema, json_schema
from .service import Service
from .session import open_session, undeclare, use_session

__all__ = ["McapLogger", "read_log", "read_metadata", "RAW_TOPIC", "LOSSES_METADATA", "ROLES_METADATA", "main"]

log = logging.getLogger(__name__)

#: Topic of the raw MAVLink frames (signature blocks stripped).
RAW_TOPIC = "/mavlink/raw"
#: Message encoding of RAW_TOPIC: one MAVLink frame per message, no schema.
RAW_ENCODING = "mavlink"
#: The metadata record with the log's loss counts, written at finish (see :meth:`McapLogger.losses`).
LOSSES_METADATA = "rapt.losses"
#: The metadata record mapping the hub's key expressions to the roles allowed to put them (a secure bus only).
ROLES_METADATA = "rapt.roles"
#: The channel metadata naming the role(s) a channel's samples came from (a secure bus only).
ROLE_KEY = "rapt.role"

_DATA_CHANNEL = 1 << 22  # samples held for the writer: a minute of 20,000 frames/s (allocated as used)
_BATCH = 4096  # samples written between checks of the flush and status clocks
_IDLE_S = 0.002  # the writer's nap when the channel is empty (a few hundred wake-ups a second, idle)

_OBJECT = {"type": "object"}
_SCHEMAS: dict[str, dict] = {
    "rapt.Json": {"type": "object", "title": "free JSON"},
    "rapt.Setpoint": {
        "type": "object",
        "title": "back-seat set-point",
        "properties": {
            "tick_ms": {"type": ["integer", "null"]},
            "vx": {"type": "number", "description": "m/s north"},
            "vy": {"type": "number", "description": "m/s east"},
            "vz": {"type": "number", "description": "m/s down"},
            "yaw": {"type": "number", "description": "rad"},
        },
    },
    "rapt.Liveliness": {"type": "object", "properties": {"alive": {"type": "boolean"}}},
}


@functools.cache
def _schema_for(kind: str, name: str) -> Schema:
    if kind in ("mavlink", "virtual"):  # a virtual message has the same fields as a real one
        return json_schema(
            f"mavlink.{name}",
            {
                "type": "object",
                "title": f"MAVLink {name}",
                "properties": {"mavpackettype": {"type": "string"}, "_recv_ns": {"type": "integer"}},
            },
        )
    if kind == "command":
        return json_schema("rapt.Setpoint", _SCHEMAS["rapt.Setpoint"])
    if kind == "alive":
        return json_schema("rapt.Liveliness", _SCHEMAS["rapt.Liveliness"])
    return json_schema("rapt.Json", _SCHEMAS["rapt.Json"])


def _as_object(payload: bytes) -> tuple[bytes, dict]:
    """(JSON bytes of an object, the object) for any payload; see the module docstring."""
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError:
        obj: dict = {"base64": base64.b64encode(payload).decode("ascii")}
        return json.dumps(obj).encode(), obj
    try:
        value = json.loads(text)
    except ValueError:
        obj = {"value": text}
        return json.dumps(obj).encode(), obj
    if isinstance(value, dict):
        return payload, value
    obj = {"value": value}
    return json.dumps(obj).encode(), obj


class McapLogger(Service):
    """Record ``rapt/<vehicle>/**`` and its liveliness tokens to the MCAP file ``path``.

    ``session``: an open ``zenoh.Session`` (left open), a ``zenoh.Config``, or None for an
    in-process session of its own. ``roles``: on a secure bus, ``{key expression: [roles]}``
    allowed to put (:func:`bridge.channel_roles.put_roles` of the hub's rules). Use as a context manager or call :meth:`start`/:meth:`close`
    (:class:`~bridge.service.Service`).
    """

    _what = "logger"

    def __init__(
        self,
        path: str | Path,
        session: zenoh.Session | zenoh.Config | None = None,
        *,
        vehicle: str = keys.DEFAULT_VEHICLE,
        chunk_size: int = 64 * 1024,
        flush_interval_s: float = 1.0,
        compression: str = "zstd",
        roles: dict[str, list[str]] | None = None,
    ):
        super().__init__()
        keys.everything(vehicle)  # validates the name
        if not (isinstance(chunk_size, int) and chunk_size > 0):
            raise InputError(f"chunk_size: expected an int > 0, got {chunk_size!r}")
        if not (isinstance(flush_interval_s, (int, float)) and flush_interval_s > 0):
            raise InputError(f"flush_interval_s: expected a number > 0, got {flush_interval_s!r}")
        codecs = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
        if compression not in codecs:
            raise InputError(f"compression: expected one of {sorted(codecs)}, got {compression!r}")
        self.path = Path(path)
        self.vehicle = vehicle
        self.chunk_size = chunk_size
        self.flush_interval_s = float(flush_interval_s)
        self._compression = codecs[compression]
        self._roles = None if roles is None else ChannelRoles(roles)
        self._session_arg = session
        self._session: zenoh.Session | None = None
        self._owns_session = False
        self._liveliness: collections.deque = collections.deque()  # liveliness changes, for the writer
        self._liveliness_done = threading.Event()
        self._subs: list[Any] = []
        self._status_pub: Any = None
        self._bus_gaps = PublicationGaps()
        self._bridge_status_key = keys.status(vehicle, "bridge")
        self._own_status_key = keys.status(vehicle, "logger")
        self._lost_said = 0  # the total last warned about
        self._bridges: dict[Any, tuple[dict, dict]] = {}  # started_ns -> (first, last) status of a bridge
        self._token: Any = None
        self._writer_thread: threading.Thread | None = None
        self._file: Any = None
        self._writer: Writer | None = None
        self._mcap: McapChannels | None = None  # the file's channels, from _open
        self._counts = dict.fromkeys(("written", "metadata", "errors", "flushes", "derived"), 0)
        self._foxglove = foxglove.FoxgloveMessages()
        self._received = [0, 0]  # per drain thread (data, liveliness): no shared counter between threads

    # ----------------------------------------------------------------- life cycle
    def _open(self) -> None:
        """Open the file, subscribe, start the threads."""
        self._file = open(self.path, "wb")
        self._writer = writer = Writer(self._file, chunk_size=self.chunk_size, compression=self._compression)
        writer.start(profile="", library="rapt-bridge")
        self._mcap = McapChannels(writer)
        if self._roles is not None:
            by_expr = {k: ",".join(v) for k, v in self._roles.by_key_expr.items()}
            writer.add_metadata(ROLES_METADATA, {**by_expr, "(any other key)": HUB})
        self._session, self._owns_session = use_session(self._session_arg)
        s = self._session
        self._status_pub = s.declare_publisher(
            keys.status(self.vehicle, "logger"), encoding=zenoh.Encoding.APPLICATION_JSON
        )
        data = s.declare_subscriber(keys.everything(self.vehicle), zenoh.handlers.FifoChannel(_DATA_CHANNEL))
        self._subs = [data]
        alive = s.liveliness().declare_subscriber(
            keys.alive(self.vehicle, "*"), zenoh.handlers.FifoChannel(1024), history=True
        )
        self._subs.append(alive)
        self._writer_thread = self._spawn("mcap-writer", self._write_loop, writer, data.handler)
        self._spawn("mcap-liveliness", self._drain_liveliness, alive.handler)
        self._token = s.liveliness().declare_token(keys.alive(self.vehicle, "logger"))

    def _shutdown(self) -> None:
        """Stop receiving, write what was received, the losses, finish the MCAP file (summary + footer)."""
        undeclare(self._token, *self._subs)
        self._join((t for t in self._threads if t is not self._writer_thread), timeout=10)  # liveliness
        self._liveliness_done.set()
        if self._writer_thread is not None:
            self._writer_thread.join(timeout=60)
        if self._writer is not None:
            if self._writer_thread is None or not self._writer_thread.is_alive():
                losses = {k: v if isinstance(v, str) else json.dumps(v) for k, v in self._say_losses().items()}
                self._writer.add_metadata(LOSSES_METADATA, losses)
            self._writer.finish()
        undeclare(self._status_pub)
        if self._file is not None:
            self._file.close()
        if self._owns_session and self._session is not None:
            self._session.close()

    @property
    def stats(self) -> dict[str, int]:
        """received (samples off Zenoh), written (MCAP messages of them), metadata, errors, flushes, queued,
        derived (Foxglove messages written beside them)."""
        out = {"received": sum(self._received), **self._counts}
        out["queued"] = len(self._liveliness)
        out["bus_lost"] = self._bus_gaps.lost
        return out

    def losses(self) -> dict[str, Any]:
        """What this log is missing, as ``rapt.losses`` records it (the values as JSON-ready numbers).

        From the bridge's ``status/bridge`` (counted from the first status this logger saw of
        each bridge to the last; "unknown" without any): ``link_seq_gaps``, MAVLink sequence
        numbers that never reached the bridge, and ``kernel_dropped``, datagrams its UDP socket
        had no room for. A burst of 256 or more lost frames hides from a modulo-256 counter
        while the kernel's count is exact, so ``link_lost`` is the larger of the two (exact when
        one cause is at work, a lower bound when both are). From the logger itself: ``bus_lost``
        (bridge publications that never arrived) and ``write_errors``. ``total`` is link_lost +
        bus_lost + write_errors.
        """
        gaps: int | str = "unknown"
        kernel: int | str = "unknown"
        by_source: dict[str, int] = {}
        if self._bridges:
            gaps = kernel = 0
            for first, last in list(self._bridges.values()):
                gaps += int(last.get("link_lost", 0)) - int(first.get("link_lost", 0))
                if isinstance(kernel, int) and int(last.get("kernel_dropped", -1)) >= 0:
                    kernel += int(last["kernel_dropped"]) - max(0, int(first.get("kernel_dropped", 0)))
                else:
                    kernel = "unknown"
                before = first.get("link_lost_by_source") or {}
                for source, n in (last.get("link_lost_by_source") or {}).items():
                    by_source[source] = by_source.get(source, 0) + int(n) - int(before.get(source, 0))
        link = gaps if not isinstance(gaps, int) or not isinstance(kernel, int) else max(gaps, kernel)
        bus, errors = self._bus_gaps.lost, self._counts["errors"]
        return {
            "total": (link if isinstance(link, int) else 0) + bus + errors,
            "link_lost": link,
            "link_seq_gaps": gaps,
            "link_lost_by_source": by_source,
            "kernel_dropped": kernel,
            "bus_lost": bus,
            "bus_lost_by_key": dict(self._bus_gaps.by_key),
            "write_errors": errors,
            "received": sum(self._received),
            "written": self._counts["written"],
        }

    # ----------------------------------------------------------------- threads
    def _drain_liveliness(self, handler: Any) -> None:
        """Hand liveliness changes to the writer (they come on a channel of their own)."""
        while True:
            try:
                sample = handler.recv()
            except zenoh.ZError:  # undeclared: closing
                return
            self._received[1] += 1
            self._liveliness.append((str(sample.key_expr), time.time_ns(), None, sample.kind == zenoh.SampleKind.PUT))

    def _write_loop(self, writer: Writer, data: Any) -> None:
        """The one thread that writes ``writer``: the samples on the ``data`` channel as they come (no
        hand-over between threads: at 40,000 samples/s that costs more than writing them), liveliness
        changes, a flush every ``flush_interval_s`` and the status once a second. Ends when ``data``
        is undeclared and empty."""
        try_recv, liveliness = data.try_recv, self._liveliness
        next_flush = next_status = time.monotonic()
        dirty = closed = False
        while not closed:
            n = 0
            while n < _BATCH:
                try:
                    sample = try_recv()
                except zenoh.ZError:  # undeclared, and everything taken: closing
                    closed = True
                    break
                if sample is None:
                    break
                n += 1
                self._take(writer, sample)
            closed = closed and self._liveliness_done.is_set()
            while liveliness:
                self._write_checked(writer, *liveliness.popleft())
                n += 1
            dirty = dirty or n > 0
            now = time.monotonic()
            if now >= next_flush:
                if dirty:
                    writer.flush()
                    self._counts["flushes"] += 1
                    dirty = False
                next_flush = now + self.flush_interval_s
            if now >= next_status:
                self._publish_status()
                next_status = now + 1.0
            if n == 0 and not closed:
                time.sleep(_IDLE_S)

    def _take(self, writer: Writer, sample: Any) -> None:
        """One sample off the bus: count a gap in its publisher's numbers, note a bridge status, write it.

        The logger's own status is not logged: what it counts ends up in ``rapt.losses``."""
        key = str(sample.key_expr)
        if key == self._own_status_key:
            return
        self._received[0] += 1
        now = time.time_ns()
        attachment = sample.attachment
        if attachment is not None:  # a bridge publication's number (keys.sequence_attachment), or not one
            number = keys.attachment_sequence(attachment.to_bytes())
            if number is not None:
                self._bus_gaps.see(key, number)
        payload = sample.payload.to_bytes()
        put = sample.kind == zenoh.SampleKind.PUT
        if key == self._bridge_status_key and put:
            self._on_bridge_status(payload)
        self._write_checked(writer, key, now, payload, put)

    def _write_checked(self, writer: Writer, key: str, recv_ns: int, payload: bytes | None, put: bool) -> None:
        try:
            self._write(writer, key, recv_ns, payload, put)
        except Exception:  # one bad sample must not stop the log
            self._counts["errors"] += 1
            log.exception("logger: cannot write a sample on %s", key)

    def _on_bridge_status(self, payload: bytes) -> None:
        try:
            status = json.loads(payload)
            started = status["started_ns"]
        except (ValueError, TypeError, KeyError):
            return
        first = self._bridges.get(started, (status, status))[0]
        self._bridges[started] = (first, status)

    def _publish_status(self) -> None:
        losses = self._say_losses()
        try:
            self._status_pub.put(json.dumps({**self.stats, **losses}))
        except Exception as error:  # a closing session
            log.debug("logger: status not published: %s", error)

    def _say_losses(self) -> dict[str, Any]:
        """:meth:`losses`, and a warning on the console when their total changed since the last one."""
        losses = self.losses()
        if losses["total"] != self._lost_said:  # said on the console too, not only on the bus and in the log
            log.warning(
                "logger %s: %d frame(s) lost on the way to %s so far (link %s, bus %d, write errors %d)",
                self.vehicle,
                losses["total"],
                self.path.name,
                losses["link_lost"],
                losses["bus_lost"],
                losses["write_errors"],
            )
            self._lost_said = losses["total"]
        return losses

    def _write(self, w: Writer, key: str, recv_ns: int, payload: bytes | None, put: bool) -> None:
        try:
            _, kind, name = keys.split(key)
        except ValueError:
            kind, name = "", key
        mcap = self._mcap
        assert mcap is not None, "written only after _open"
        source: dict | None = None  # the JSON object Foxglove messages are derived from
        if payload is None:  # liveliness change
            channel_id, seq = mcap.channel(key, "json", _schema_for("alive", name), self._role_of(key))
            data = json.dumps({"alive": put}).encode()
            publish_ns = recv_ns
        elif kind == "mavlink" and name == "raw":
            channel_id, seq = mcap.channel(RAW_TOPIC, RAW_ENCODING, None, self._role_of(key))
            data = strip_signature(payload)
            publish_ns = recv_ns
        else:
            if put:
                data, obj = _as_object(payload)
                source = obj
            else:
                obj = {"deleted": True}
                data = json.dumps(obj).encode()
            stamp = obj.get("_recv_ns")
            publish_ns = stamp if isinstance(stamp, int) and not isinstance(stamp, bool) else recv_ns
            if kind == "map":  # the document is logged as its foxglove.GeoJSON channel only
                document = obj if put else {"type": "FeatureCollection", "features": []}  # deleted: an empty map
                self._write_foxglove(self._foxglove.derive(kind, name, document, publish_ns), recv_ns, "written")
                return
            channel_id, seq = mcap.channel(key, "json", _schema_for(kind, name), self._role_of(key))
            if kind == "meta" and put:
                w.add_metadata(name, {str(k): v if isinstance(v, str) else json.dumps(v) for k, v in obj.items()})
                self._counts["metadata"] += 1
        w.add_message(channel_id, log_time=recv_ns, data=data, publish_time=publish_ns, sequence=seq[0])
        seq[0] += 1
        self._counts["written"] += 1
        if source is not None:
            self._write_foxglove(self._foxglove.derive(kind, name, source, publish_ns), recv_ns, "derived")

    def _role_of(self, key: str) -> dict[str, str] | None:
        """The channel metadata naming who may have put ``key`` (None off a secure bus)."""
        return None if self._roles is None else {ROLE_KEY: self._roles(key)}

    def _write_foxglove(self, derived: list[foxglove.Derived], recv_ns: int, counter: str) -> None:
        """The Foxglove messages derived from one sample (:mod:`bridge.foxglove`), written beside it."""
        mcap = self._mcap
        assert mcap is not None, "written only after _open"
        for topic, schema_name, message in derived:
            mcap.add_foxglove(topic, schema_name, message, recv_ns, recv_ns)
            self._counts[counter] += 1


# --------------------------------------------------------------------------- reading
def _decode(channel: Any, data: bytes) -> Any:
    return json.loads(data) if channel.message_encoding == "json" else bytes(data)


def read_log(path: str | Path, topics: Sequence[str] | None = None) -> list[tuple[str, int, Any]]:
    """``[(topic, log_time_ns, payload)]`` in file order; JSON as dicts, raw frames as bytes.

    ``topics`` keeps only those topics, and decodes nothing else (a range day's log holds
    millions of messages; the pack's reports are a few thousand of them).  A file without a
    footer (the logger was killed) is read linearly up to its last complete chunk.
    """
    path = Path(path)
    wanted = None if topics is None else set(topics)
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            reader.get_summary()
            found = reader.iter_messages(topics=None if wanted is None else list(wanted), log_time_order=False)
            return [(c.topic, m.log_time, _decode(c, m.data)) for _, c, m in found]
        except McapError:
            f.seek(0)
        out = []
        try:
            for _, c, m in NonSeekingReader(f).iter_messages(log_time_order=False):
                if wanted is None or c.topic in wanted:
                    out.append((c.topic, m.log_time, _decode(c, m.data)))
        except EndOfFile:
            pass
        return out


def read_metadata(path: str | Path) -> dict[str, dict[str, str]]:
    """``{name: {key: str}}`` from the MCAP metadata records (a later record of a name wins)."""
    path = Path(path)
    out: dict[str, dict[str, str]] = {}
    with open(path, "rb") as f:
        try:
            reader = make_reader(f)
            reader.get_summary()
            for record in reader.iter_metadata():
                out[record.name] = dict(record.metadata)
            return out
        except McapError:
            f.seek(0)
            out.clear()
        try:
            for record in NonSeekingReader(f).iter_metadata():
                out[record.name] = dict(record.metadata)
        except EndOfFile:
            pass
        return out


# --------------------------------------------------------------------------- command line
def main(argv: list[str] | None = None) -> int:
    """``python -m bridge.logger OUT.mcap --connect tcp/127.0.0.1:7447``: log until SIGINT/SIGTERM."""
    parser = argparse.ArgumentParser(prog="python -m bridge.logger", description=main.__doc__)
    parser.add_argument("path", type=Path)
    parser.add_argument("--vehicle", default=keys.DEFAULT_VEHICLE)
    parser.add_argument("--connect", action="append", default=[], help="Zenoh endpoint to connect to")
    parser.add_argument("--listen", action="append", default=[], help="Zenoh endpoint to listen on")
    parser.add_argument("--config", type=Path, default=None, help="Zenoh config file (taken as-is)")
    parser.add_argument("--flush-interval", type=float, default=1.0)
    parser.add_argument("--chunk-size", type=int, default=64 * 1024)
    args = parser.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    with open_session(args.listen, args.connect, args.config) as session:
        with McapLogger(
            args.path, session, vehicle=args.vehicle, chunk_size=args.chunk_size, flush_interval_s=args.flush_interval
        ) as logger:
            print("ready", flush=True)
            while not stop.wait(0.5):
                pass
            stats = logger.stats
    print(json.dumps(stats), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
