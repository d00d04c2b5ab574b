"""One MAVLink link (the vehicle's front-seat) joined to the Zenoh bus, with the safety gates between.

Every valid frame goes out as raw bytes and as JSON per message type; set-points from the
active back-seat source come back as ``SET_POSITION_TARGET_LOCAL_NED`` (velocity + yaw). On a
real vehicle nothing reaches MAVLink unless ``allow_commands`` is set, the vehicle is heard
from, the set-point does not push it out of the geofence and the rate limit allows it: the
gates of :class:`bridge.command_gate.CommandGate`, which the bridge asks for every set-point. The
link may drop or go silent at any time: the bridge then forwards nothing and keeps reopening
the connection until frames come back.

An operator's bring-up runs through the same object, under the same gates (``allow_commands``,
an autopilot heard within ``silence_s``; each call checks its arguments and the gates before
anything is sent): :meth:`MavlinkBridge.latest` and :attr:`MavlinkBridge.autopilot` read the
latest message of each type, :meth:`~MavlinkBridge.command_long` (and ``set_mode``, ``arm``,
``set_message_interval`` on top of it) waits for the final COMMAND_ACK,
:meth:`~MavlinkBridge.request_data_stream` sets a stream group's rate and
:meth:`~MavlinkBridge.upload_mission` runs :mod:`bridge.mission_upload`'s protocol, the reader
thread handing it the vehicle's MISSION_REQUEST(_INT) and MISSION_ACK as it hands COMMAND_ACK
to a waiting command.

Benchmarking the round trip: a vehicle stamps ``time_boot_ms`` on a telemetry message, the
back-seat echoes it as the set-point's ``tick_ms``, and the vehicle receives it back as
``SET_POSITION_TARGET_LOCAL_NED.time_boot_ms``; wall time between the two, measured at the
vehicle, is the MAVLink -> Zenoh -> back-seat -> Zenoh -> MAVLink latency. ``stats`` holds
every counter a benchmark needs to check that nothing was refused or dropped on the way.
A set-point from a source that is not the active one is counted (``commands_inactive``) and
logged once per source. On the range's secure bus the hub's access rules drop what a role may
not put before the bridge sees it; eclipse-zenoh 1.10.2 reports those refusals only in its own
log, at trace level beside every allowed message ("... CertCommonName(logger) ... is
unauthorized to Put (ingress) on rapt/uuv1/control/active" with
``RUST_LOG=zenoh::net::routing::interceptor::access_control=trace``), with no counter or
callback a bridge could read, so the bridge counts only what reaches it.

Nothing is lost silently (:mod:`bridge.loss`): gaps in each sender's MAVLink sequence numbers
are counted (``link_lost``), a UDP link's socket gets a receive buffer for bursts and its
kernel drops are read back (``kernel_dropped``), every publication carries its number on its
key (:func:`bridge.keys.sequence_attachment`) so the logger counts what the bus lost, and
frames go out with Zenoh's BLOCK congestion control (a slow subscriber slows the bridge, whose
socket buffer then absorbs the burst, rather than Zenoh dropping samples). The counters are
published on ``status/bridge`` once a second and when the bridge closes.
"""

from __future__ import annotations

import json
import logging
import math
import os
import queue
import select
import socket
import threading
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

import zenoh  # noqa: E402
from pymavlink import mavutil  # noqa: E402

from rapt.errors import FileFormatError, InputError, LinkError, LinkTimeoutError, RefusedError, RunError  # noqa: E402

from . import keys  # noqa: E402
from .command_gate import CommandGate  # noqa: E402
from .frames import FrameSplitter, mavlink2, message_json  # noqa: E402
from .loss import SequenceGaps, frame_source_seq, udp_drops  # noqa: E402
from .mission_upload import COUNT, MissionItem, MissionUpload, describe, mission_items  # noqa: E402
from .service import Service  # noqa: E402
from .session import undeclare, use_session  # noqa: E402
from .setpoint import Setpoint  # noqa: E402

__all__ = ["MavlinkBridge", "Autopilot", "MissionItem", "ARDUSUB_MODES", "TYPE_MASK_VELOCITY_YAW", "load_signing_key"]

log = logging.getLogger(__name__)

#: ArduSub ``Mode::Number`` (ArduSub/mode.h).
ARDUSUB_MODES = {
    "STABILIZE": 0,
    "ACRO": 1,
    "ALT_HOLD": 2,
    "AUTO": 3,
    "GUIDED": 4,
    "CIRCLE": 7,
    "SURFACE": 9,
    "POSHOLD": 16,
    "MANUAL": 19,
    "MOTOR_DETECT": 20,
    "SURFTRAK": 21,
}

#: Ignore position (1|2|4), acceleration (64|128|256) and yaw rate (2048): velocity + yaw.
TYPE_MASK_VELOCITY_YAW = 2503

_DIALECT = "ardupilotmega"
_MISSION_REPLIES = frozenset(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"))
_REPLIES = _MISSION_REPLIES | {"COMMAND_ACK"}  # the messages a waiting command or upload is handed
_POLL_S = 0.1  # idle wake-up: silence detection and resync of a stalled partial frame
_MAX_BACKOFF_S = 0.5
#: Receive buffer asked for a UDP link: seconds of 20,000 small frames/s. Without root
#: (SO_RCVBUFFORCE) the kernel caps it at net.core.rmem_max; ``stats["rcvbuf_bytes"]`` says what was granted.
UDP_RCVBUF_BYTES = 32 << 20
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux
_DRAIN_DATAGRAMS = 256  # datagrams read per wake-up under load (one select per burst, not per frame)
_BLOCK = zenoh.CongestionControl.BLOCK


def load_signing_key(signing_key: bytes | str | os.PathLike) -> bytes:
    """A 32-byte MAVLink2 signing key from bytes, or from a file of 32 bytes or 64 hex digits."""
    if isinstance(signing_key, (bytes, bytearray)):
        if len(signing_key) != 32:
            raise InputError(f"signing_key: expected 32 bytes, got {len(signing_key)}")
        return bytes(signing_key)
    if not isinstance(signing_key, (str, os.PathLike)):
        raise TypeError(f"signing_key: expected 32 bytes or a key file path, got {type(signing_key).__name__}")
    path = Path(signing_key)
    if not path.is_file():
        raise FileFormatError(f"signing_key: {str(path)!r} is not a file")
    data = path.read_bytes()
    if len(data) == 32:
        return data
    text = data.strip()
    if len(text) == 64:
        try:
            return bytes.fromhex(text.decode("ascii"))
        except (ValueError, UnicodeDecodeError):
            pass
    raise FileFormatError(f"signing_key: {str(path)!r} holds neither 32 bytes nor 64 hex digits")


@dataclass(frozen=True)
class Autopilot:
    """The autopilot's latest HEARTBEAT: MAV_TYPE, MAV_AUTOPILOT, base_mode flags, custom_mode
    (the ArduSub mode number), MAV_STATE, and when it arrived (``time.monotonic()``)."""

    type: int
    autopilot: int
    base_mode: int
    custom_mode: int
    system_status: int
    monotonic_s: float

    @property
    def armed(self) -> bool:
        return bool(self.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> str | None:
        """The ArduSub mode's name (see :data:`ARDUSUB_MODES`), None for a number ArduSub does not define."""
        for name, number in ARDUSUB_MODES.items():
            if number == self.custom_mode:
                return name
        return None

    @property
    def mode_label(self) -> str:
        """The mode as a message names it: its name, or "mode N" for a number ArduSub does not define."""
        return self.mode or f"mode {self.custom_mode}"


def _mode_number(name: str) -> int:
    number = ARDUSUB_MODES.get(str(name).strip().upper())
    if number is None:
        raise InputError(f"required_mode: unknown ArduSub mode {name!r} (known: {', '.join(ARDUSUB_MODES)})")
    return number


def _is_int(value: Any, low: int, high: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class MavlinkBridge(Service):
    """Bridge one pymavlink connection (``udpin:``, ``udpout:``, ``tcp:``, ``tcpin:``, serial) to Zenoh.

    ``session`` is an open ``zenoh.Session`` (not closed by the bridge), a ``zenoh.Config``
    or None (the bridge opens and closes its own session; None means in-process only).
    ``required_mode`` (e.g. ``"GUIDED"``) forwards set-points only while the autopilot's last
    HEARTBEAT reports that mode. Use as a context manager, or call :meth:`start` and :meth:`close` (:class:`~bridge.service.Service`).
    """

    _what = "bridge"

    def __init__(
        self,
        device: str,
        session: zenoh.Session | zenoh.Config | None = None,
        *,
        vehicle: str = keys.DEFAULT_VEHICLE,
        allow_commands: bool = False,
        geofence: Sequence[float] | None = None,
        geofence_margin_m: float = 20.0,
        max_rate_hz: float | None = None,
        required_mode: str | None = None,
        signing_key: bytes | str | os.PathLike | None = None,
        silence_s: float = 2.0,
        heartbeat_hz: float = 1.0,
        source_system: int = 1,
        source_component: int = mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER,
        baud: int = 115200,
        status_interval_s: float = 1.0,
    ):
        if not isinstance(device, str) or not device:
            raise InputError(f"device: expected a pymavlink connection string, got {device!r}")
        super().__init__()
        keys.raw(vehicle)  # validates the name
        #: The command gates (allow_commands, link, geofence, rate, active source); a watchdog may ask it too.
        self.gate = CommandGate(
            allow_commands=allow_commands,
            silence_s=silence_s,
            geofence=geofence,
            geofence_margin_m=geofence_margin_m,
            max_rate_hz=max_rate_hz,
            required_mode=_mode_number(required_mode) if required_mode is not None else None,
        )
        if not (isinstance(heartbeat_hz, (int, float)) and heartbeat_hz > 0):
            raise InputError(f"heartbeat_hz: expected a number > 0, got {heartbeat_hz!r}")
        if not (_is_number(status_interval_s) and status_interval_s > 0):
            raise InputError(f"status_interval_s: expected a number of seconds > 0, got {status_interval_s!r}")
        self.status_interval_s = float(status_interval_s)
        for name, value in (("source_system", source_system), ("source_component", source_component)):
            if not (isinstance(value, int) and 1 <= value <= 255):
                raise InputError(f"{name}: expected an int in 1..255, got {value!r}")
        self.device = device
        self.vehicle = vehicle
        self.heartbeat_hz = float(heartbeat_hz)
        self.source_system = source_system
        self.source_component = source_component
        self.baud = baud
        self._key = None if signing_key is None else load_signing_key(signing_key)
        self._session_arg = session

        self._session: zenoh.Session | None = None
        self._owns_session = False
        self._conn: Any = None
        self._datagram = device.startswith(("udp:", "udpin:", "udpout:", "udpbcast:", "mcast:"))
        self._send_lock = threading.Lock()
        self._wake_r: socket.socket | None = None  # wakes the reader thread on close()
        self._wake_w: socket.socket | None = None
        self._splitter = FrameSplitter(self._decode)
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._numbers: dict[str, int] = {}  # per telemetry publisher: the next publication's number
        self._raw_pub: zenoh.Publisher | None = None
        self._raw_number = 0
        self._status_pub: zenoh.Publisher | None = None
        self._started_ns = time.time_ns()  # tells this bridge's status apart from a restarted one's
        self._gaps = SequenceGaps()
        self._rcvbuf = 0
        self._kernel_dropped_before = 0  # kernel drops of the UDP sockets closed so far
        self._lost_said = (0, 0)  # the losses last warned about
        self._refused_sources: set[str] = set()  # sources whose set-points were refused (logged once each)
        self._cmd_sub: Any = None
        self._active_sub: Any = None
        self._cmd_handler: Any = None
        self._active_handler: Any = None
        self._opened_at = time.monotonic()
        self._token: Any = None
        self._active_lock = threading.Lock()
        self._target: tuple[int, int] | None = None
        self._position: tuple[float, float, float] | None = None  # north, east, monotonic time
        self._last_frame = -math.inf
        self._heard = False  # frames seen on the current connection
        self._lost = False  # a link loss happened after frames were seen
        # the latest message of each type from the autopilot's system: written by the reader thread
        # only (one dict store per frame), read anywhere; replaced by an empty dict when the link is lost
        self._latest: dict[str, tuple[Any, float]] = {}
        self._acks: dict[int, tuple[int, int, int]] = {}  # command -> (result, progress, serial)
        self._ack_cond = threading.Condition()
        self._ack_serial = 0
        self._mission_lock = threading.Lock()  # one upload at a time
        self._mission_inbox: queue.SimpleQueue | None = None  # the running upload's replies, from the reader
        self._counts = dict.fromkeys(
            (
                "frames_in",
                "frames_out",
                "heartbeats_out",
                "published",
                "publish_errors",
                "commands_in",
                "commands_inactive",
                "commands_invalid",
                "commands_refused",
                "commands_stale",
                "commands_geofence",
                "commands_rate_limited",
                "commands_mode",
                "commands_forwarded",
                "reconnects",
                "link_losses",
                "reopens",
                "open_failures",
            ),
            0,
        )

    # ----------------------------------------------------------------- life cycle
    def __repr__(self) -> str:
        return (
            f"MavlinkBridge({self.device!r}, vehicle={self.vehicle!r}, allow_commands={self.allow_commands}, "
            f"signed={self._key is not None})"
        )

    def _open(self) -> None:
        """Open the session entities and the link, then start the reader, command, heartbeat and status threads."""
        self._wake_r, self._wake_w = socket.socketpair()
        self._session, self._owns_session = use_session(self._session_arg)
        s, v = self._session, self.vehicle
        self._raw_pub = s.declare_publisher(
            keys.raw(v),
            encoding=zenoh.Encoding.APPLICATION_OCTET_STREAM,
            reliability=zenoh.Reliability.RELIABLE,
            congestion_control=_BLOCK,
        )
        self._status_pub = s.declare_publisher(keys.status(v, "bridge"), encoding=zenoh.Encoding.APPLICATION_JSON)
        self._cmd_sub = s.declare_subscriber(keys.command(v, "*"), zenoh.handlers.FifoChannel(4096))
        self._active_sub = s.declare_subscriber(keys.active(v), zenoh.handlers.FifoChannel(256))
        # Handlers are read by our threads; the subscriber objects are only touched here and in close().
        self._cmd_handler = self._cmd_sub.handler
        self._active_handler = self._active_sub.handler
        self._token = s.liveliness().declare_token(keys.alive(v, "bridge"))
        try:
            self._open_link()
        except (OSError, ConnectionError) as error:  # the reader thread keeps trying
            log.warning("bridge %s: cannot open %s yet (%s); retrying", v, self.device, error)
            self._counts["open_failures"] += 1
        self._spawn(f"bridge-{v}-reader", self._read_loop)
        self._spawn(f"bridge-{v}-commands", self._command_loop)
        self._spawn(f"bridge-{v}-heartbeat", self._heartbeat_loop)
        self._spawn(f"bridge-{v}-status", self._status_loop)

    def _shutdown(self) -> None:
        """Stop the threads, close the link, publish the last status, undeclare everything, close an owned session."""
        if self._wake_w is not None:
            try:
                self._wake_w.send(b"x")
            except OSError:
                pass
        undeclare(self._cmd_sub, self._active_sub)
        self._join(self._threads, timeout=5)
        with self._send_lock:
            self._close_conn()
        self._publish_status()
        undeclare(self._token, self._raw_pub, self._status_pub, *self._publishers.values())
        self._publishers.clear()
        if self._owns_session and self._session is not None:
            self._session.close()
        for sock in (self._wake_r, self._wake_w):
            if sock is not None:
                sock.close()

    # ----------------------------------------------------------------- configuration (the gate's)
    @property
    def allow_commands(self) -> bool:
        """Whether set-points and COMMAND_LONGs may reach the vehicle at all."""
        return self.gate.allow_commands

    @property
    def geofence(self) -> tuple[float, float, float, float] | None:
        """(north_min, north_max, east_min, east_max) in metres, or None."""
        return self.gate.geofence

    @property
    def geofence_margin_m(self) -> float:
        return self.gate.geofence_margin_m

    @property
    def max_rate_hz(self) -> float | None:
        return self.gate.max_rate_hz

    @property
    def silence_s(self) -> float:
        """A link with no valid frame for this long is reopened, and commands are refused as stale."""
        return self.gate.silence_s

    # ----------------------------------------------------------------- state
    @property
    def stats(self) -> dict[str, int]:
        """Counters: frames in/out, bad frames, refused unsigned frames, commands by fate, reconnects,
        and losses: ``link_lost`` (MAVLink sequence numbers that never came, all senders; late frames
        taken back off), ``link_late``, ``link_duplicates``, ``kernel_dropped`` (datagrams a UDP
        socket had no room for; -1 where unknown) and ``rcvbuf_bytes`` (the UDP receive buffer granted)."""
        out = dict(self._counts)
        sp, gaps = self._splitter, self._gaps
        kernel = self._kernel_dropped()
        out.update(
            bad_frames=sp.bad_frames,
            bad_bytes=sp.bad_bytes,
            unsigned_refused=sp.unsigned,
            bad_signature=sp.bad_signature,
            link_lost=gaps.lost,
            link_late=gaps.late,
            link_duplicates=gaps.duplicates,
            kernel_dropped=-1 if kernel is None else kernel,
            rcvbuf_bytes=self._rcvbuf,
        )
        return out

    @property
    def link_lost_by_source(self) -> dict[str, int]:
        """MAVLink frames lost per sender, ``{"system/component": lost}``."""
        return self._gaps.as_dict()["by_source"]

    def _kernel_dropped(self) -> int | None:
        conn = self._conn
        if not self._datagram:
            return None
        if conn is None or getattr(conn, "port", None) is None:
            return self._kernel_dropped_before
        try:
            now = udp_drops(conn.port.fileno())
        except (OSError, ValueError):
            now = 0
        return None if now is None else self._kernel_dropped_before + now

    def status(self) -> dict[str, Any]:
        """What ``status/bridge`` carries: :attr:`stats`, the losses per sender, and this bridge's start time
        (``started_ns``; counters restart with a new bridge)."""
        return {"started_ns": self._started_ns, **self.stats, "link_lost_by_source": self.link_lost_by_source}

    def _publish_status(self) -> None:
        pub = self._status_pub
        if pub is None:
            return
        status = self.status()
        lost = (status["link_lost"], max(0, status["kernel_dropped"]))
        if lost != self._lost_said:  # said out loud, not only on the bus: an operator may watch only the console
            log.warning(
                "bridge %s: MAVLink frames lost so far: %d by sequence gaps, %d dropped by the UDP socket "
                "(%s frames received)",
                self.vehicle,
                *lost,
                status["frames_in"],
            )
            self._lost_said = lost
        try:
            pub.put(json.dumps(status))
        except Exception as error:  # a closing session
            log.debug("bridge %s: status not published: %s", self.vehicle, error)

    def _status_loop(self) -> None:
        self._publish_status()  # counters start at zero: a logger already up sees where they start
        while not self._stop.wait(self.status_interval_s):
            self._publish_status()

    @property
    def linked(self) -> bool:
        """A frame arrived within ``silence_s`` and an autopilot HEARTBEAT gave the target."""
        return self._target is not None and time.monotonic() - self._last_frame <= self.silence_s

    @property
    def target(self) -> tuple[int, int] | None:
        """(system, component) of the autopilot, from its HEARTBEAT."""
        return self._target

    @property
    def autopilot(self) -> Autopilot | None:
        """The autopilot's latest HEARTBEAT (type, autopilot, base_mode, custom_mode, system_status), or None."""
        latest = self._latest.get("HEARTBEAT")
        if latest is None:
            return None
        msg, at = latest
        return Autopilot(msg.type, msg.autopilot, msg.base_mode, msg.custom_mode, msg.system_status, at)

    def latest(self, name: str) -> tuple[Any, float] | None:
        """``(message, time.monotonic() at arrival)``: the latest ``name`` message (e.g. ``"EKF_STATUS_REPORT"``)
        from the autopilot's system, like pymavlink's ``conn.messages``; None if none came since the
        autopilot was last heard (a lost link forgets them all). Cheap, and safe from any thread."""
        if not isinstance(name, str) or not name:
            raise InputError(f"name: expected a MAVLink message name such as 'HEARTBEAT', got {name!r}")
        return self._latest.get(name)

    @property
    def active(self) -> str:
        """The source whose set-points are forwarded."""
        self._drain_active()
        return self.gate.active

    # ----------------------------------------------------------------- MAVLink link
    def _open_link(self) -> None:
        try:
            conn = mavutil.mavlink_connection(
                self.device,
                baud=self.baud,
                source_system=self.source_system,
                source_component=self.source_component,
                dialect=_DIALECT,
                autoreconnect=False,
                retries=0,
            )
        except ImportError as error:  # pymavlink imports pyserial only for serial ports
            raise RunError(f"device: {self.device!r} is a serial port and needs pyserial ({error})") from None
        if isinstance(conn, mavutil.mavudp):
            self._rcvbuf = _grow_rcvbuf(conn.port, UDP_RCVBUF_BYTES)
        if self._key is not None:
            conn.setup_signing(self._key, sign_outgoing=True, allow_unsigned_callback=_refuse_unsigned)
        with self._send_lock:
            self._conn = conn
        self._splitter.reset()
        self._heard = False
        self._opened_at = time.monotonic()

    def _close_conn(self) -> None:
        if self._datagram and self._conn is not None:
            self._kernel_dropped_before = self._kernel_dropped() or 0
        conn, self._conn = self._conn, None
        if conn is not None:
            try:
                conn.close()
            except Exception:  # closing a dead serial port or socket may raise
                pass

    def _link_lost(self, reason: str) -> None:
        log.info("bridge %s: link lost (%s); reopening %s", self.vehicle, reason, self.device)
        if self._heard:
            self._lost = True
            self._counts["link_losses"] += 1
        self._last_frame = -math.inf
        self._target = None  # nothing stale: a vehicle that comes back announces itself again
        self._position = None
        self._latest = {}
        with self._send_lock:
            self._close_conn()

    def _decode(self, buf: bytearray) -> Any:
        conn = self._conn
        if self._key is None:
            return conn.mav.decode(buf)
        with self._send_lock:  # signing timestamps are shared with the sending side
            return conn.mav.decode(buf)

    def _read_loop(self) -> None:
        backoff = 0.05
        while not self._stop.is_set():
            conn = self._conn
            if conn is None:
                try:
                    self._open_link()
                    self._counts["reopens"] += 1
                    backoff = 0.05
                except Exception as error:  # OSError, SerialException, ...: keep trying
                    self._counts["open_failures"] += 1
                    log.debug("bridge %s: reopen failed: %s", self.vehicle, error)
                    if self._stop.wait(backoff):
                        break
                    backoff = min(2 * backoff, _MAX_BACKOFF_S)
                continue
            try:
                fd = conn.fd
                readable = select.select([fd, self._wake_r], [], [], _POLL_S)[0]
            except (OSError, ValueError, TypeError) as error:
                self._link_lost(f"select: {error}")
                continue
            if self._wake_r in readable:
                break
            if fd in readable:
                accepting = isinstance(conn, mavutil.mavtcpin) and conn.port is None
                try:
                    if isinstance(conn, mavutil.mavtcp):
                        data = conn.port.recv(65536)  # pymavlink's recv hides EOF behind a print
                    else:
                        data = conn.recv(65536)
                except BlockingIOError:
                    continue
                except Exception as error:  # OSError, SerialException
                    self._link_lost(str(error) or type(error).__name__)
                    continue
                if not data:
                    if not (accepting or self._datagram):
                        self._link_lost("end of stream")
                    continue
                recv_ns = time.time_ns()
                for frame, msg in self._splitter.feed(data, datagram=self._datagram):
                    self._on_frame(frame, msg, recv_ns)
                if self._datagram:
                    self._drain_datagrams(conn)
            elif self._splitter.pending:  # idle with a partial frame held back: junk, not a frame
                recv_ns = time.time_ns()
                for frame, msg in self._splitter.resync():
                    self._on_frame(frame, msg, recv_ns)
            # no valid frame for silence_s (even if junk or refused frames keep coming): reopen
            quiet_since = self._last_frame if self._heard else self._opened_at
            if time.monotonic() - quiet_since > self.silence_s:
                self._link_lost("silent")

    def _drain_datagrams(self, conn: Any) -> None:
        """Read the datagrams already queued on a UDP socket (up to a bound) without a select for each."""
        feed, on_frame = self._splitter.feed, self._on_frame
        for _ in range(_DRAIN_DATAGRAMS):
            try:
                data = conn.recv(65536)  # non-blocking: "" when nothing is left
            except BlockingIOError:
                return
            except Exception as error:  # OSError
                self._link_lost(str(error) or type(error).__name__)
                return
            if not data:
                return
            recv_ns = time.time_ns()
            for frame, msg in feed(data, datagram=True):
                on_frame(frame, msg, recv_ns)

    def _on_frame(self, frame: bytes, msg: Any, recv_ns: int) -> None:
        """Note what the bridge keeps of one frame (target, position, latest, replies) and publish it."""
        self._gaps.see(*frame_source_seq(frame))
        now = time.monotonic()
        if self._lost:
            self._lost = False
            self._counts["reconnects"] += 1
            log.info("bridge %s: link back", self.vehicle)
        self._heard = True
        self._last_frame = now
        self._counts["frames_in"] += 1
        name = msg.get_type()
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if name == "HEARTBEAT":
            if msg.autopilot != mavlink2.MAV_AUTOPILOT_INVALID:
                self._target = source
        elif name == "LOCAL_POSITION_NED":
            self._position = (msg.x, msg.y, now)
        target = self._target
        if target is not None and source[0] == target[0]:
            if name != "HEARTBEAT" or source == target:  # another component's heartbeat is not the autopilot's
                self._latest[name] = (msg, now)
            if name in _REPLIES and source == target and self._addressed_to_us(msg):
                if name == "COMMAND_ACK":
                    with self._ack_cond:
                        self._ack_serial += 1
                        self._acks[msg.command] = (msg.result, msg.progress, self._ack_serial)
                        self._ack_cond.notify_all()
                elif name in _MISSION_REPLIES:
                    inbox = self._mission_inbox
                    if inbox is not None:
                        inbox.put(msg)
        try:
            session, raw_pub = self._session, self._raw_pub
            assert session is not None and raw_pub is not None, "the reader starts after _open declared both"
            pub = self._publishers.get(name)
            if pub is None:
                pub = session.declare_publisher(
                    keys.telemetry(self.vehicle, name),
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
            log.warning("bridge %s: cannot publish %s: %s", self.vehicle, name, error)

    def _addressed_to_us(self, msg: Any) -> bool:
        """A reply addressed to this bridge (or broadcast, as some autopilots send COMMAND_ACK)."""
        system = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        return system in (0, self.source_system) and component in (0, self.source_component)

    def _send(self, msg: Any) -> bool:
        """Send under the lock; False when there is no open connection."""
        with self._send_lock:
            conn = self._conn
            if conn is None:
                return False
            conn.mav.send(msg)
            self._counts["frames_out"] += 1
            return True

    # ----------------------------------------------------------------- heartbeat
    def _heartbeat_loop(self) -> None:
        period = 1.0 / self.heartbeat_hz
        while not self._stop.is_set():
            msg = mavlink2.MAVLink_heartbeat_message(
                mavlink2.MAV_TYPE_ONBOARD_CONTROLLER,
                mavlink2.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink2.MAV_STATE_ACTIVE,
                3,
            )
            try:
                if self._send(msg):
                    self._counts["heartbeats_out"] += 1
            except Exception as error:  # a write on a dying link
                log.debug("bridge %s: heartbeat not sent: %s", self.vehicle, error)
            if self._stop.wait(period):
                break

    # ----------------------------------------------------------------- commands
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
                    self.gate.active = keys.DEFAULT_ACTIVE
                    continue
                try:
                    name = sample.payload.to_bytes().decode("utf-8").strip()
                    keys.command(self.vehicle, name)
                except ValueError:
                    log.warning("bridge %s: ignoring an invalid active source", self.vehicle)
                    continue
                if name != self.gate.active:
                    log.info("bridge %s: the active source is now %r", self.vehicle, name)
                self.gate.active = name

    def _command_loop(self) -> None:
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
                log.exception("bridge %s: command handling failed", self.vehicle)

    def _on_command(self, sample: Any) -> None:
        c = self._counts
        c["commands_in"] += 1
        if sample.kind != zenoh.SampleKind.PUT:
            return
        source = str(sample.key_expr).rsplit("/", 1)[-1]
        reason = self.gate.check_source(source)
        if reason is not None:
            c["commands_" + reason] += 1
            if source not in self._refused_sources:  # said once per source: a standby autonomy puts all run long
                self._refused_sources.add(source)
                log.warning(
                    "bridge %s: refusing set-points from %r: the active source is %r (counted in commands_%s)",
                    self.vehicle,
                    source,
                    self.gate.active,
                    reason,
                )
            return
        try:
            sp = Setpoint.from_json(sample.payload.to_bytes())
        except ValueError as error:
            c["commands_invalid"] += 1
            log.debug("bridge %s: invalid set-point from %s: %s", self.vehicle, source, error)
            return
        now = time.monotonic()
        target = self._target
        heard = None if target is None else self._last_frame
        hb = self.autopilot
        reason = self.gate.check(sp, now, self._position, heard, None if hb is None else hb.custom_mode)
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
        if self._send(msg):
            c["commands_forwarded"] += 1
        else:
            c["commands_stale"] += 1

    # ----------------------------------------------------------------- commands to the autopilot
    # Every one checks its arguments, then the gates (allow_commands, an autopilot heard within
    # silence_s), before anything is sent: nothing but HEARTBEAT reaches a vehicle otherwise.
    def _ready(self, what: str) -> tuple[int, int]:
        """The autopilot's (system, component), once the gates allow a command; otherwise a one-line error."""
        if not self.allow_commands:
            self._counts["commands_refused"] += 1
            raise RefusedError(f"{what}: allow_commands is False, nothing but HEARTBEAT is sent to the vehicle")
        target = self._target  # read once: the reader may forget it (link lost) at any time
        if target is None or not self.linked:
            raise LinkError(f"{what}: no autopilot heard within the last {self.silence_s} s")
        return target

    def _send_or_raise(self, msg: Any, what: str) -> None:
        if not self._send(msg):
            raise LinkError(f"{what}: the link to {self.device} closed; nothing was sent")

    def arm(self, armed: bool = True, *, force: bool = False, timeout: float = 1.0, retries: int = 3) -> int:
        """Arm (or disarm) with MAV_CMD_COMPONENT_ARM_DISARM; returns the COMMAND_ACK result (0 = accepted)."""
        params = (1.0 if armed else 0.0, 21196.0 if force else 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return self._command_long(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, params, timeout, retries, "arm")

    def set_mode(self, mode: str | int, *, timeout: float = 1.0, retries: int = 3) -> int:
        """Switch ArduSub mode (name like "GUIDED" or number) with MAV_CMD_DO_SET_MODE; returns the ACK result."""
        if isinstance(mode, str):
            number = ARDUSUB_MODES.get(mode.strip().upper())
            if number is None:
                raise InputError(f"mode: unknown ArduSub mode {mode!r} (known: {', '.join(ARDUSUB_MODES)})")
        elif isinstance(mode, int) and not isinstance(mode, bool) and mode in ARDUSUB_MODES.values():
            number = mode
        else:
            raise InputError(f"mode: expected an ArduSub mode name or number, got {mode!r}")
        params = (float(mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED), float(number), 0.0, 0.0, 0.0, 0.0, 0.0)
        return self._command_long(mavlink2.MAV_CMD_DO_SET_MODE, params, timeout, retries, "set_mode")

    def command_long(
        self, command: int, params: Sequence[float] = (), *, timeout: float = 1.0, retries: int = 3
    ) -> int:
        """Send COMMAND_LONG ``command`` (a MAV_CMD) with up to 7 ``params`` (the rest 0) and return its final
        COMMAND_ACK result (a MAV_RESULT: 0 accepted, 3 unsupported, 4 failed, ...).

        Sent again up to ``retries`` times while no COMMAND_ACK comes within ``timeout`` seconds
        (the ``confirmation`` field counts the tries). A ``MAV_RESULT_IN_PROGRESS`` ACK stops the
        retries and restarts the timeout: the final ACK is awaited (``latest("COMMAND_ACK")``
        shows the progress). Raises RefusedError (allow_commands False), LinkError (no autopilot
        heard) before sending anything, and LinkTimeoutError when no final ACK comes.
        """
        if not _is_int(command, 0, 0xFFFF):
            raise InputError(f"command: expected a MAV_CMD number in 0..65535, got {command!r}")
        if isinstance(params, (str, bytes)) or not isinstance(params, Sequence) or len(params) > 7:
            raise InputError(f"params: expected a sequence of at most 7 numbers, got {params!r}")
        for i, value in enumerate(params):
            if not _is_number(value):
                raise InputError(
                    f"params[{i}]: expected a number (NaN allowed where the command says so), got {value!r}"
                )
        full = [float(v) for v in params] + [0.0] * (7 - len(params))
        return self._command_long(command, full, timeout, retries, "command_long")

    def set_message_interval(self, msg_id: int, rate_hz: float, *, timeout: float = 1.0, retries: int = 3) -> int:
        """Ask for message ``msg_id`` at ``rate_hz`` (0 stops it) with MAV_CMD_SET_MESSAGE_INTERVAL (511);
        returns the COMMAND_ACK result. Rates are in the vehicle's time: an ArduSub SITL at speed-up S
        sends S times as many per wall second. A vehicle that answers MAV_RESULT_UNSUPPORTED (3)
        may still take :meth:`request_data_stream`."""
        if not _is_int(msg_id, 0, 0xFFFFFF):
            raise InputError(f"msg_id: expected a MAVLink message id in 0..16777215, got {msg_id!r}")
        if not (_is_number(rate_hz) and math.isfinite(rate_hz) and rate_hz >= 0):
            raise InputError(f"rate_hz: expected a rate >= 0 (0 stops the message), got {rate_hz!r}")
        interval_us = -1 if rate_hz == 0 else max(1, round(1e6 / rate_hz))
        if interval_us > 2**31 - 1:
            raise InputError(f"rate_hz: {rate_hz!r} is below the slowest rate MAVLink can ask for (1 per 2147 s)")
        params = (float(msg_id), float(interval_us), 0.0, 0.0, 0.0, 0.0, 0.0)
        return self._command_long(
            mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL, params, timeout, retries, "set_message_interval"
        )

    def request_data_stream(self, stream_id: int, rate_hz: int, start: bool = True) -> None:
        """Start (or stop) a MAV_DATA_STREAM group at ``rate_hz`` with REQUEST_DATA_STREAM (66), the older
        way ArduPilot and MAVProxy set rates. No reply exists: check the rate in :meth:`latest`."""
        if not _is_int(stream_id, 0, 0xFF):
            raise InputError(f"stream_id: expected a MAV_DATA_STREAM number in 0..255, got {stream_id!r}")
        if not _is_int(rate_hz, 0, 0xFFFF):
            raise InputError(f"rate_hz: expected an int rate in 0..65535 Hz, got {rate_hz!r}")
        if not isinstance(start, bool):
            raise InputError(f"start: expected True (start) or False (stop), got {start!r}")
        target = self._ready("request_data_stream")
        msg = mavlink2.MAVLink_request_data_stream_message(target[0], target[1], stream_id, rate_hz, int(start))
        self._send_or_raise(msg, "request_data_stream")

    def _command_long(self, command: int, params: Sequence[float], timeout: float, retries: int, what: str) -> int:
        if not (_is_number(timeout) and timeout > 0):
            raise InputError(f"timeout: expected a number of seconds > 0, got {timeout!r}")
        if not _is_int(retries, 0, 1000):
            raise InputError(f"retries: expected an int in 0..1000, got {retries!r}")
        target = self._ready(what)
        progress: int | None = None  # set once the vehicle reports MAV_RESULT_IN_PROGRESS
        for attempt in range(retries + 1):
            with self._ack_cond:
                serial = self._ack_serial
            msg = mavlink2.MAVLink_command_long_message(target[0], target[1], command, min(attempt, 255), *params)
            self._send(msg)
            deadline = time.monotonic() + timeout
            with self._ack_cond:
                while True:
                    ack = self._acks.get(command)
                    if ack is not None and ack[2] > serial:
                        if ack[0] != mavlink2.MAV_RESULT_IN_PROGRESS:
                            return ack[0]
                        # running: sending it again would restart or be refused; wait for the final ACK
                        serial, progress = ack[2], ack[1]
                        deadline = time.monotonic() + timeout
                    remaining = deadline - time.monotonic()
                    if self._stop.is_set():
                        raise LinkError(f"{what}: the bridge closed while waiting for COMMAND_ACK")
                    if remaining <= 0:
                        break
                    self._ack_cond.wait(remaining)
            if progress is not None:
                shown = "progress unknown" if progress == 255 else f"{progress}% done"
                raise LinkTimeoutError(
                    f"{what}: command {command} is IN_PROGRESS ({shown}) but no final COMMAND_ACK came within {timeout:g} s"
                )
        raise LinkTimeoutError(f"{what}: no COMMAND_ACK after {retries + 1} tries")

    # ----------------------------------------------------------------- mission upload
    def upload_mission(
        self,
        items: Iterable[MissionItem | Any],
        *,
        mission_type: int = mavlink2.MAV_MISSION_TYPE_MISSION,
        timeout: float = 1.5,
        retries: int = 5,
    ) -> int:
        """Upload ``items`` (:class:`MissionItem` or ``MAVLink_mission_item_int_message``, item i with seq i) with
        MAVLink's mission protocol; returns the MAV_MISSION_RESULT (0 = MAV_MISSION_ACCEPTED).

        On ArduPilot item 0 is home, and the vehicle keeps its own home there. ``mission_type``:
        0 mission, 1 fence, 2 rally. ``timeout`` runs from the vehicle's last progress; the last
        message is sent again up to ``retries`` times before LinkTimeoutError names the step.
        An empty list clears the mission. The protocol's rules are :mod:`bridge.mission_upload`'s.
        """
        what = "upload_mission"
        checked = mission_items(items)
        upload = MissionUpload(len(checked), mission_type=mission_type, timeout_s=timeout, retries=retries, what=what)
        target = self._ready(what)
        if not self._mission_lock.acquire(blocking=False):
            raise RunError(f"{what}: another upload is running on this bridge; wait for it to end")
        inbox: queue.SimpleQueue = queue.SimpleQueue()
        try:
            self._mission_inbox = inbox  # before MISSION_COUNT goes out: the first request may come at once
            self._send_mission(upload.start(time.monotonic()), checked, target, mission_type)
            while not upload.done:
                if self._stop.is_set():
                    raise LinkError(f"{what}: the bridge closed during the upload ({upload.step})")
                now = time.monotonic()
                if now >= upload.deadline:
                    sends = upload.on_timeout(now)  # raises once the retries are spent
                else:
                    try:
                        msg = inbox.get(timeout=min(upload.deadline - now, _POLL_S))
                    except queue.Empty:
                        continue
                    now = time.monotonic()
                    if msg.get_type() == "MISSION_ACK":
                        sends = upload.on_ack(msg.type, msg.mission_type, now)
                        if msg.type != mavlink2.MAV_MISSION_ACCEPTED:
                            log.info("bridge %s: %s NACK %s (%s)", self.vehicle, what, describe(msg.type), upload.step)
                    else:
                        sends = upload.on_request(msg.seq, msg.mission_type, now)
                self._send_mission(sends, checked, target, mission_type)
        finally:
            self._mission_inbox = None
            self._mission_lock.release()
        assert upload.result is not None, "the loop ends only when the upload is done"
        if upload.result != mavlink2.MAV_MISSION_ACCEPTED:
            log.warning("bridge %s: %s ended with %s", self.vehicle, what, describe(upload.result))
        return upload.result

    def _send_mission(self, sends: list[int], items: list[MissionItem], target: tuple[int, int], kind: int) -> None:
        for seq in sends:
            if seq == COUNT:
                msg = mavlink2.MAVLink_mission_count_message(target[0], target[1], len(items), kind)
            else:
                msg = items[seq].to_message(target[0], target[1], kind)
            self._send(msg)  # a closed link is a timeout for the upload, as a lost frame is


def _grow_rcvbuf(sock: socket.socket, size: int) -> int:
    """Ask for a ``size``-byte receive buffer (forced past net.core.rmem_max where allowed); the size granted."""
    for option in (_SO_RCVBUFFORCE, socket.SO_RCVBUF):
        try:
            sock.setsockopt(socket.SOL_SOCKET, option, size)
            break
        except OSError:
            continue
    granted = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    if granted < size:
        log.info("bridge: UDP receive buffer %d bytes of %d asked (raise net.core.rmem_max for bursts)", granted, size)
    return granted


def _refuse_unsigned(mav: Any, msg_id: int) -> bool:
    return False
