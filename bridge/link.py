"""The MAVLink link to the vehicle's front-seat: one pymavlink connection, kept open, read and counted.

:class:`MavlinkLink` owns the connection (``udpin:``, ``udpout:``, ``tcp:``, ``tcpin:``, serial),
its MAVLink 2 signing, the bridge's HEARTBEAT and one reader thread. The reader cuts frames
out of the byte stream (:class:`bridge.frames.FrameSplitter`), notes who the autopilot is and
the latest message of each type it sent, hands the replies a waiting command expects to a
:class:`ReplySink` and every frame to a :class:`FrameSink` (the relay to the bus). The link
may drop or go silent at any time: the reader then forgets the autopilot and keeps reopening
the connection until frames come back.

Nothing is lost silently (:mod:`bridge.loss`): gaps in each sender's MAVLink sequence numbers
are counted (``link_lost``), a UDP link's socket gets a receive buffer for bursts and its
kernel drops are read back (``kernel_dropped``).
"""

from __future__ import annotations

import logging
import math
import os
import select
import socket
import threading
import time
from pathlib import Path
from typing import Any, Protocol

os.environ.setdefault("MAVLINK20", "1")

from pymavlink import mavutil  # noqa: E402

from rapt.errors import FileFormatError, InputError, RunError  # noqa: E402

from .frames import FrameSplitter, mavlink2  # noqa: E402
from .loss import SequenceGaps, frame_source_seq, udp_drops  # noqa: E402

__all__ = ["FrameSink", "MavlinkLink", "ReplySink", "UDP_RCVBUF_BYTES", "load_signing_key"]

log = logging.getLogger(__name__)

_DIALECT = "ardupilotmega"
POLL_S = 0.1  # idle wake-up: silence detection and resync of a stalled partial frame
_MAX_BACKOFF_S = 0.5
#: Receive buffer asked for a UDP link: seconds of 20,000 small frames/s. Without root
#: (SO_RCVBUFFORCE) the kernel caps it at net.core.rmem_max; ``stats["rcvbuf_bytes"]`` says what was granted.
UDP_RCVBUF_BYTES = 32 << 20
_SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux
_DRAIN_DATAGRAMS = 256  # datagrams read per wake-up under load (one select per burst, not per frame)


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


class ReplySink(Protocol):
    """Where the reader hands the autopilot's replies addressed to this side (a waiting command's mailbox)."""

    #: The message types it takes (e.g. COMMAND_ACK); the reader hands over nothing else.
    names: frozenset[str]

    def deliver(self, msg: Any) -> None: ...


class FrameSink(Protocol):
    """Where the reader hands every valid frame (the relay to the bus), on the reader thread."""

    def on_frame(self, frame: bytes, msg: Any, name: str, recv_ns: int, now: float) -> None:
        """One frame: its bytes, the decoded message, its type, wall-clock ns and monotonic s at arrival."""

    def on_link_lost(self) -> None:
        """The link was lost: forget whatever the last connection said."""


class MavlinkLink:
    """One pymavlink connection to the front-seat, reopened whenever it drops or stays silent for ``silence_s``.

    ``counts`` is the bridge's counter table; the link counts ``frames_in``, ``frames_out``,
    ``heartbeats_out``, ``reconnects``, ``link_losses``, ``reopens`` and ``open_failures`` in
    it. ``stop`` ends the reader and heartbeat loops. ``signing_key`` (32 bytes, see
    :func:`load_signing_key`) signs what goes out and refuses unsigned frames.
    """

    def __init__(
        self,
        device: str,
        *,
        replies: ReplySink,
        counts: dict[str, int],
        stop: threading.Event,
        silence_s: float,
        heartbeat_hz: float,
        source_system: int,
        source_component: int,
        baud: int,
        signing_key: bytes | None,
        vehicle: str,
    ):
        self.device = device
        self.vehicle = vehicle  # names the link in the log
        self.silence_s = silence_s
        self.heartbeat_hz = heartbeat_hz
        self.source_system = source_system
        self.source_component = source_component
        self.baud = baud
        self._key = signing_key
        #: with a key: take unsigned frames (not badly signed ones) until the vehicle holds the key too
        self.accept_unsigned = False
        self._badsig_seen = 0
        self._replies = replies
        self._counts = counts
        self._stop = stop
        self._frames: FrameSink | None = None  # set as the reader starts
        self._conn: Any = None
        self._datagram = device.startswith(("udp:", "udpin:", "udpout:", "udpbcast:", "mcast:"))
        self._send_lock = threading.Lock()
        self._wake_r: socket.socket | None = None  # wakes the reader thread on close()
        self._wake_w: socket.socket | None = None
        self._splitter = FrameSplitter(self._decode)
        self._gaps = SequenceGaps()
        self._rcvbuf = 0
        self._kernel_dropped_before = 0  # kernel drops of the UDP sockets closed so far
        self._opened_at = time.monotonic()
        self._target: tuple[int, int] | None = None
        self._last_frame = -math.inf
        self._heard = False  # frames seen on the current connection
        self._lost = False  # a link loss happened after frames were seen
        # the latest message of each type from the autopilot's system: written by the reader thread
        # only (one dict store per frame), read anywhere; replaced by an empty dict when the link is lost
        self._latest: dict[str, tuple[Any, float]] = {}

    @property
    def signed(self) -> bool:
        """MAVLink 2 signing is on."""
        return self._key is not None

    # ----------------------------------------------------------------- life cycle
    def open(self) -> None:
        """Make the reader's wake-up pair and try to open the connection (the reader keeps trying if it fails)."""
        self._wake_r, self._wake_w = socket.socketpair()
        try:
            self._open_link()
        except (OSError, ConnectionError) as error:  # the reader thread keeps trying
            log.warning("bridge %s: cannot open %s yet (%s); retrying", self.vehicle, self.device, error)
            self._counts["open_failures"] += 1

    def wake(self) -> None:
        """Wake the reader thread so that it sees the stop event."""
        if self._wake_w is not None:
            try:
                self._wake_w.send(b"x")
            except OSError:
                pass

    def close(self) -> None:
        """Close the connection and the wake-up pair (after the reader has ended)."""
        with self._send_lock:
            self._close_conn()
        for sock in (self._wake_r, self._wake_w):
            if sock is not None:
                sock.close()

    # ----------------------------------------------------------------- state
    @property
    def linked(self) -> bool:
        """A frame arrived within ``silence_s`` and an autopilot HEARTBEAT gave the target."""
        return self._target is not None and time.monotonic() - self._last_frame <= self.silence_s

    @property
    def target(self) -> tuple[int, int] | None:
        """(system, component) of the autopilot, from its HEARTBEAT."""
        return self._target

    @property
    def last_frame(self) -> float:
        """Monotonic time of the last valid frame (``-inf`` while none came on this connection)."""
        return self._last_frame

    def latest(self, name: str) -> tuple[Any, float] | None:
        """``(message, time.monotonic() at arrival)``: the latest ``name`` message (e.g. ``"EKF_STATUS_REPORT"``)
        from the autopilot's system, like pymavlink's ``conn.messages``; None if none came since the
        autopilot was last heard (a lost link forgets them all). Cheap, and safe from any thread."""
        if not isinstance(name, str) or not name:
            raise InputError(f"name: expected a MAVLink message name such as 'HEARTBEAT', got {name!r}")
        return self._latest.get(name)

    def frame_stats(self) -> dict[str, int]:
        """The link's share of the bridge's stats: bad and refused frames, losses, the UDP buffer granted."""
        sp, gaps = self._splitter, self._gaps
        kernel = self._kernel_dropped()
        return {
            "bad_frames": sp.bad_frames,
            "bad_bytes": sp.bad_bytes,
            "unsigned_refused": sp.unsigned,
            "bad_signature": sp.bad_signature,
            "link_lost": gaps.lost,
            "link_late": gaps.late,
            "link_duplicates": gaps.duplicates,
            "kernel_dropped": -1 if kernel is None else kernel,
            "rcvbuf_bytes": self._rcvbuf,
        }

    @property
    def lost_by_source(self) -> dict[str, int]:
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

    # ----------------------------------------------------------------- the connection
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
            conn.setup_signing(self._key, sign_outgoing=True, allow_unsigned_callback=self._unsigned_allowed)
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
        if self._frames is not None:
            self._frames.on_link_lost()
        self._latest = {}
        with self._send_lock:
            self._close_conn()

    def _decode(self, buf: bytearray) -> Any:
        conn = self._conn
        if self._key is None:
            return conn.mav.decode(buf)
        with self._send_lock:  # signing timestamps are shared with the sending side
            return conn.mav.decode(buf)

    def _unsigned_allowed(self, mav: Any, msg_id: int) -> bool:
        """pymavlink's question for a frame without a good signature: an unsigned one passes only while
        :attr:`accept_unsigned`; a badly signed one (pymavlink has just counted it) never."""
        bad = mav.signing.badsig_count
        if bad != self._badsig_seen:
            self._badsig_seen = bad
            return False
        return self.accept_unsigned

    @property
    def signing_timestamp(self) -> int:
        """Our signing clock (10 µs since 2015-01-01), for SETUP_SIGNING; 0 when not signing or not open."""
        with self._send_lock:
            conn = self._conn
            return 0 if conn is None or self._key is None else int(conn.mav.signing.timestamp)

    @property
    def signing_key(self) -> bytes | None:
        return self._key

    def send_unsigned(self, msg: Any) -> bool:
        """Send one message unsigned (a probe of whether the vehicle accepts unsigned messages on this link)."""
        with self._send_lock:
            conn = self._conn
            if conn is None:
                return False
            signing = conn.mav.signing
            was, signing.sign_outgoing = signing.sign_outgoing, False
            try:
                conn.mav.send(msg)
            finally:
                signing.sign_outgoing = was
            self._counts["frames_out"] += 1
            return True

    def send(self, msg: Any) -> bool:
        """Send under the lock; False when there is no open connection."""
        with self._send_lock:
            conn = self._conn
            if conn is None:
                return False
            conn.mav.send(msg)
            self._counts["frames_out"] += 1
            return True

    # ----------------------------------------------------------------- the reader
    def read_loop(self, frames: FrameSink) -> None:
        """The reader thread: read, hand every frame to ``frames``, reopen a lost link, until the stop event."""
        self._frames = frames
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
                readable = select.select([fd, self._wake_r], [], [], POLL_S)[0]
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
        """Note what the link keeps of one frame (target, latest), hand over replies, then the frame itself."""
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
        if name == "HEARTBEAT" and msg.autopilot != mavlink2.MAV_AUTOPILOT_INVALID:
            self._target = source
        target = self._target
        if target is not None and source[0] == target[0]:
            if name != "HEARTBEAT" or source == target:  # another component's heartbeat is not the autopilot's
                self._latest[name] = (msg, now)
            if name in self._replies.names and source == target and self._addressed_to_us(msg):
                self._replies.deliver(msg)
        assert self._frames is not None, "frames are read only by read_loop, which sets the sink"
        self._frames.on_frame(frame, msg, name, recv_ns, now)

    def _addressed_to_us(self, msg: Any) -> bool:
        """A reply addressed to this side (or broadcast, as some autopilots send COMMAND_ACK)."""
        system = getattr(msg, "target_system", 0)
        component = getattr(msg, "target_component", 0)
        return system in (0, self.source_system) and component in (0, self.source_component)

    # ----------------------------------------------------------------- heartbeat
    def heartbeat_loop(self) -> None:
        """The heartbeat thread: this side's HEARTBEAT (an onboard controller) at ``heartbeat_hz`` (read each
        beat: bring-up raises it on a vehicle whose clock runs faster than the wall's)."""
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
                if self.send(msg):
                    self._counts["heartbeats_out"] += 1
            except Exception as error:  # a write on a dying link
                log.debug("bridge %s: heartbeat not sent: %s", self.vehicle, error)
            if self._stop.wait(1.0 / self.heartbeat_hz):
                break


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
