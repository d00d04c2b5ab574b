"""The relay between the MAVLink link and the Zenoh bus, with the set-point gate between.

Every valid frame goes out as raw bytes and as JSON per message type; set-points from the
active back-seat source come back as ``SET_POSITION_TARGET_LOCAL_NED`` (velocity + yaw). On a
real vehicle nothing reaches MAVLink unless ``allow_commands`` is set, the vehicle is heard
from, the set-point does not push it out of the geofence and the rate limit allows it: the
gates of :class:`bridge.command_gate.CommandGate`, which the relay asks for every set-point.
While the link is down the relay forwards nothing.

Benchmarking the round trip: a vehicle stamps ``time_boot_ms`` on a telemetry message, the
back-seat echoes it as the set-point's ``tick_ms``, and the vehicle receives it back as
``SET_POSITION_TARGET_LOCAL_NED.time_boot_ms``; wall time between the two, measured at the
vehicle, is the MAVLink -> Zenoh -> back-seat -> Zenoh -> MAVLink latency. The bridge's
``stats`` hold every counter a benchmark needs to check that nothing was refused or dropped on
the way. A set-point from a source that is not the active one is counted
(``commands_inactive``) and logged once per source. On the range's secure bus the hub's access
rules drop what a role may not put before the bridge sees it; eclipse-zenoh 1.10.2 reports
those refusals only in its own log, at trace level beside every allowed message ("...
CertCommonName(logger) ... is unauthorized to Put (ingress) on rapt/uuv1/control/active" with
``RUST_LOG=zenoh::net::routing::interceptor::access_control=trace``), with no counter or
callback a bridge could read, so the bridge counts only what reaches it.

Nothing is lost silently: every publication carries its number on its key
(:func:`bridge.keys.sequence_attachment`) so the logger counts what the bus lost, and frames go
out with Zenoh's BLOCK congestion control (a slow subscriber slows the bridge, whose socket
buffer then absorbs the burst, rather than Zenoh dropping samples). The counters are published
on ``status/bridge`` every ``status_interval_s`` and when the bridge closes.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from . import keys
from .command_gate import CommandGate
from .frames import mavlink2, message_json
from .link import MavlinkLink
from .session import undeclare, use_session
from .setpoint import Setpoint

__all__ = ["BusRelay", "TYPE_MASK_VELOCITY_YAW"]

log = logging.getLogger(__name__)

#: Ignore position (1|2|4), acceleration (64|128|256) and yaw rate (2048): velocity + yaw.
TYPE_MASK_VELOCITY_YAW = 2503

_BLOCK = zenoh.CongestionControl.BLOCK


class BusRelay:
    """Relay ``link``'s frames to the bus of ``vehicle`` and the active source's set-points back through ``gate``.

    A :class:`bridge.link.FrameSink` for the link's reader. ``counts`` is the bridge's counter
    table (``published``, ``publish_errors`` and ``commands_*``); ``status`` gives what
    ``status/bridge`` carries, published every ``status_interval_s`` until ``stop`` is set.
    """

    def __init__(
        self,
        link: MavlinkLink,
        gate: CommandGate,
        *,
        vehicle: str,
        counts: dict[str, int],
        stop: threading.Event,
        status: Callable[[], dict[str, Any]],
        status_interval_s: float,
    ):
        self._link = link
        self._gate = gate
        self._vehicle = vehicle
        self._counts = counts
        self._stop = stop
        self._status = status
        self._status_interval_s = status_interval_s
        self._session: zenoh.Session | None = None
        self._owns_session = False
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._numbers: dict[str, int] = {}  # per telemetry publisher: the next publication's number
        self._raw_pub: zenoh.Publisher | None = None
        self._raw_number = 0
        self._status_pub: zenoh.Publisher | None = None
        self._lost_said = (0, 0)  # the losses last warned about
        self._refused_sources: set[str] = set()  # sources whose set-points were refused (logged once each)
        self._cmd_sub: Any = None
        self._active_sub: Any = None
        self._cmd_handler: Any = None
        self._active_handler: Any = None
        self._token: Any = None
        self._active_lock = threading.Lock()
        self._position: tuple[float, float, float] | None = None  # north, east, monotonic time

    @property
    def position(self) -> tuple[float, float, float] | None:
        """The vehicle's last LOCAL_POSITION_NED as (north, east, monotonic time), None since the link was lost."""
        return self._position

    @property
    def active(self) -> str:
        """The source whose set-points are forwarded."""
        self._drain_active()
        return self._gate.active

    # ----------------------------------------------------------------- life cycle
    def open(self, session: zenoh.Session | zenoh.Config | None) -> None:
        """Open (or use) the session and declare the publishers, subscribers and liveliness token."""
        self._session, self._owns_session = use_session(session)
        s, v = self._session, self._vehicle
        self._raw_pub = s.declare_publisher(
            keys.raw(v),
            encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM,
            reliability=zenoh.Reliability.RELIABLE,
            congestion_control=_BLOCK,
        )
        self._status_pub = s.declare_publisher(keys.status(v, "bridge"), encoding=zenoh.Encoding.APPLICATION_JSON)
        self._cmd_sub = s.declare_subscriber(keys.command(v, "*"), zenoh.handlers.FifoChannel(4096))
        self._active_sub = s.declare_subscriber(keys.active(v), zenoh.handlers.FifoChannel(256))
        # Handlers are read by our threads; the subscriber objects are only touched here and in stop_listening().
        self._cmd_handler = self._cmd_sub.handler
        self._active_handler = self._active_sub.handler
        self._token = s.liveliness().declare_token(keys.alive(v, "bridge"))

    def stop_listening(self) -> None:
        """Undeclare the subscribers: the command thread ends."""
        undeclare(self._cmd_sub, self._active_sub)

    def close(self) -> None:
        """Publish the last status, undeclare everything, close an owned session."""
        self.publish_status()
        undeclare(self._token, self._raw_pub, self._status_pub, *self._publishers.values())
        self._publishers.clear()
        if self._owns_session and self._session is not None:
            self._session.close()

    # ----------------------------------------------------------------- MAVLink -> bus
    def on_frame(self, frame: bytes, msg: Any, name: str, recv_ns: int, now: float) -> None:
        """Note the vehicle's position and publish one frame as JSON and raw bytes (on the link's reader thread)."""
        if name == "LOCAL_POSITION_NED":
            self._position = (msg.x, msg.y, now)
        try:
            session, raw_pub = self._session, self._raw_pub
            assert session is not None and raw_pub is not None, "the reader starts after open declared both"
            pub = self._publishers.get(name)
            if pub is None:
                pub = session.declare_publisher(
                    keys.telemetry(self._vehicle, name),
                    encoding=zenoh.Encoding.APPLICATION_JSON,
                    reliability=zenoh.Reliability.RELIABLE,
                    congestion_control=_BLOCK,
                )  # not express: batching keeps bursts lossless, and costs no measurable latency
                self._publishers[name] = pub
                self._numbers[name] = 0
            # numbered as keys.sequence_attachment does (inlined: this runs 20,000 times a second)
            number = self._numbers[name]
            pub.put(message_json(msg, recv_ns), attachment=number.to_bytes(8, "little"))
            self._numbers[name] = number + 1
            self._counts["published"] += 1
            raw_pub.put(frame, attachment=self._raw_number.to_bytes(8, "little"))
            self._raw_number += 1
            self._counts["published"] += 1
        except Exception as error:  # a closing session, an unencodable field: count, keep reading
            self._counts["publish_errors"] += 1
            log.warning("bridge %s: cannot publish %s: %s", self._vehicle, name, error)

    def on_link_lost(self) -> None:
        """Forget the position: a vehicle that comes back says where it is again."""
        self._position = None

    # ----------------------------------------------------------------- status
    def publish_status(self) -> None:
        """Put the status on ``status/bridge``, and say new losses in the log."""
        pub = self._status_pub
        if pub is None:
            return
        status = self._status()
        lost = (status["link_lost"], max(0, status["kernel_dropped"]))
        if lost != self._lost_said:  # said out loud, not only on the bus: an operator may watch only the console
            log.warning(
                "bridge %s: MAVLink frames lost so far: %d by sequence gaps, %d dropped by the UDP socket "
                "(%s frames received)",
                self._vehicle,
                *lost,
                status["frames_in"],
            )
            self._lost_said = lost
        try:
            pub.put(json.dumps(status))
        except Exception as error:  # a closing session
            log.debug("bridge %s: status not published: %s", self._vehicle, error)

    def status_loop(self) -> None:
        """The status thread."""
        self.publish_status()  # counters start at zero: a logger already up sees where they start
        while not self._stop.wait(self._status_interval_s):
            self.publish_status()

    # ----------------------------------------------------------------- bus -> MAVLink
    def _drain_active(self) -> None:
        handler = self._active_handler
        if handler is None:
            return
        with self._active_lock:
            while True:
                try:
                    sample = handler.try_recv()
                except zenoh.ZError:
                    return
                if sample is None:
                    return
                if sample.kind == zenoh.SampleKind.DELETE:
                    self._gate.active = keys.DEFAULT_ACTIVE
                    continue
                try:
                    name = sample.payload.to_bytes().decode("utf-8").strip()
                    keys.command(self._vehicle, name)
                except ValueError:
                    log.warning("bridge %s: ignoring an invalid active source", self._vehicle)
                    continue
                if name != self._gate.active:
                    log.info("bridge %s: the active source is now %r", self._vehicle, name)
                self._gate.active = name

    def command_loop(self) -> None:
        """The command thread: each set-point through the gate, until the subscriber is undeclared."""
        handler = self._cmd_handler
        while True:
            try:
                sample = handler.recv()
            except zenoh.ZError:  # the subscriber was undeclared: closing
                return
            try:
                self._drain_active()
                self._on_command(sample)
            except Exception:  # never let one bad sample stop command handling
                log.exception("bridge %s: command handling failed", self._vehicle)

    def _on_command(self, sample: Any) -> None:
        c = self._counts
        c["commands_in"] += 1
        if sample.kind != zenoh.SampleKind.PUT:
            return
        source = str(sample.key_expr).rsplit("/", 1)[-1]
        reason = self._gate.check_source(source)
        if reason is not None:
            c["commands_" + reason] += 1
            if source not in self._refused_sources:  # said once per source: a standby autonomy puts all run long
                self._refused_sources.add(source)
                log.warning(
                    "bridge %s: refusing set-points from %r: the active source is %r (counted in commands_%s)",
                    self._vehicle,
                    source,
                    self._gate.active,
                    reason,
                )
            return
        try:
            sp = Setpoint.from_json(sample.payload.to_bytes())
        except ValueError as error:
            c["commands_invalid"] += 1
            log.debug("bridge %s: invalid set-point from %s: %s", self._vehicle, source, error)
            return
        self._forward(sp)

    def _forward(self, sp: Setpoint) -> None:
        """Send the active source's set-point as SET_POSITION_TARGET_LOCAL_NED if the gate lets it through."""
        c = self._counts
        now = time.monotonic()
        target = self._link.target
        heard = None if target is None else self._link.last_frame
        hb = self._link.latest("HEARTBEAT")
        reason = self._gate.check(sp, now, self._position, heard, None if hb is None else hb[0].custom_mode)
        if reason is not None:
            c["commands_" + reason] += 1
            return
        assert target is not None, "the gate forwards only while an autopilot is heard"
        msg = mavlink2.MAVLink_set_position_target_local_ned_message(
            sp.tick_ms or 0,
            target[0],
            target[1],
            mavlink2.MAV_FRAME_LOCAL_NED,
            TYPE_MASK_VELOCITY_YAW,
            0.0,
            0.0,
            0.0,
            sp.vx,
            sp.vy,
            sp.vz,
            0.0,
            0.0,
            0.0,
            sp.yaw,
            0.0,
        )
        if self._link.send(msg):
            c["commands_forwarded"] += 1
        else:
            c["commands_stale"] += 1
