"""One MAVLink link (the vehicle's front-seat) joined to the Zenoh bus, with the safety gates between.

:class:`MavlinkBridge` composes the three parts and owns their threads (:class:`~bridge.service.Service`):

* :class:`bridge.link.MavlinkLink` — the pymavlink connection, its reader, signing and losses;
* :class:`bridge.vehicle_commands.VehicleCommands` — an operator's bring-up (COMMAND_LONG, modes,
  stream rates, mission upload), fed the autopilot's replies by the reader through a
  :class:`~bridge.vehicle_commands.ReplyMailbox`;
* :class:`bridge.relay.BusRelay` — telemetry to the bus and the active source's set-points back,
  through :class:`bridge.command_gate.CommandGate`.

Its counters (``stats``) are one table the parts count in; they are published on
``status/bridge`` once a second and when the bridge closes.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Sequence
from typing import Any

import zenoh

from rapt.errors import InputError

from . import keys
from .command_gate import CommandGate
from .frames import mavlink2
from .link import MavlinkLink, load_signing_key
from .mission_upload import MissionItem
from .relay import BusRelay
from .service import Service
from .vehicle_commands import Autopilot, ReplyMailbox, VehicleCommands, mode_number

__all__ = ["MavlinkBridge"]

#: The bridge's counters, in the order ``stats`` and ``status/bridge`` list them.
COUNTERS = (
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
)


def _check_settings(heartbeat_hz: Any, status_interval_s: Any, source_system: Any, source_component: Any) -> None:
    """The checks of the bridge's own settings, in the order the bridge always made them."""
    if not (isinstance(heartbeat_hz, (int, float)) and heartbeat_hz > 0):
        raise InputError(f"heartbeat_hz: expected a number > 0, got {heartbeat_hz!r}")
    is_number = isinstance(status_interval_s, (int, float)) and not isinstance(status_interval_s, bool)
    if not (is_number and status_interval_s > 0):
        raise InputError(f"status_interval_s: expected a number of seconds > 0, got {status_interval_s!r}")
    for name, value in (("source_system", source_system), ("source_component", source_component)):
        if not (isinstance(value, int) and 1 <= value <= 255):
            raise InputError(f"{name}: expected an int in 1..255, got {value!r}")


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
        accept_unsigned: bool = False,
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
            required_mode=mode_number(required_mode) if required_mode is not None else None,
        )
        _check_settings(heartbeat_hz, status_interval_s, source_system, source_component)
        self.status_interval_s = float(status_interval_s)
        self.device = device
        self.vehicle = vehicle
        self._heartbeat_hz = float(heartbeat_hz)
        self.source_system = source_system
        self.source_component = source_component
        self.baud = baud
        key = None if signing_key is None else load_signing_key(signing_key)
        self._session_arg = session
        self._started_ns = time.time_ns()  # tells this bridge's status apart from a restarted one's
        self._counts = dict.fromkeys(COUNTERS, 0)
        replies = ReplyMailbox()
        self._link = MavlinkLink(
            device,
            replies=replies,
            counts=self._counts,
            stop=self._stop,
            silence_s=self.gate.silence_s,
            heartbeat_hz=self._heartbeat_hz,
            source_system=source_system,
            source_component=source_component,
            baud=baud,
            signing_key=key,
            vehicle=vehicle,
        )
        self._link.accept_unsigned = accept_unsigned  # with a key: until bring-up gives the vehicle it
        self._commands = VehicleCommands(
            self._link, replies, self.gate, counts=self._counts, stop=self._stop, vehicle=vehicle
        )
        self._relay = BusRelay(
            self._link,
            self.gate,
            vehicle=vehicle,
            counts=self._counts,
            stop=self._stop,
            status=self.status,
            status_interval_s=self.status_interval_s,
        )

    # ----------------------------------------------------------------- life cycle
    def __repr__(self) -> str:
        return (
            f"MavlinkBridge({self.device!r}, vehicle={self.vehicle!r}, allow_commands={self.allow_commands}, "
            f"signed={self._link.signed})"
        )

    def _open(self) -> None:
        """Open the bus side and the link, then start the reader, command, heartbeat and status threads."""
        self._relay.open(self._session_arg)
        self._link.open()
        v = self.vehicle
        self._spawn(f"bridge-{v}-reader", self._link.read_loop, self._relay)
        self._spawn(f"bridge-{v}-commands", self._relay.command_loop)
        self._spawn(f"bridge-{v}-heartbeat", self._link.heartbeat_loop)
        self._spawn(f"bridge-{v}-status", self._relay.status_loop)

    def _shutdown(self) -> None:
        """Stop the threads, close the link, publish the last status, undeclare everything, close an owned session."""
        self._link.wake()
        self._relay.stop_listening()
        self._join(self._threads, timeout=5)
        self._link.close()
        self._relay.close()

    # ----------------------------------------------------------------- configuration (the gate's)
    @property
    def heartbeat_hz(self) -> float:
        """This side's HEARTBEAT rate (Hz, wall clock); settable while running."""
        return self._link.heartbeat_hz

    @heartbeat_hz.setter
    def heartbeat_hz(self, hz: float) -> None:
        if not (isinstance(hz, (int, float)) and not isinstance(hz, bool) and 0 < hz <= 1000):
            raise InputError(f"heartbeat_hz: expected a number in (0, 1000] Hz, got {hz!r}")
        self._link.heartbeat_hz = float(hz)

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
        out.update(self._link.frame_stats())
        return out

    @property
    def link_lost_by_source(self) -> dict[str, int]:
        """MAVLink frames lost per sender, ``{"system/component": lost}``."""
        return self._link.lost_by_source

    def status(self) -> dict[str, Any]:
        """What ``status/bridge`` carries: :attr:`stats`, the losses per sender, and this bridge's start time
        (``started_ns``; counters restart with a new bridge)."""
        return {"started_ns": self._started_ns, **self.stats, "link_lost_by_source": self.link_lost_by_source}

    @property
    def linked(self) -> bool:
        """A frame arrived within ``silence_s`` and an autopilot HEARTBEAT gave the target."""
        return self._link.linked

    @property
    def target(self) -> tuple[int, int] | None:
        """(system, component) of the autopilot, from its HEARTBEAT."""
        return self._link.target

    @property
    def autopilot(self) -> Autopilot | None:
        """The autopilot's latest HEARTBEAT (type, autopilot, base_mode, custom_mode, system_status), or None."""
        return self._commands.autopilot

    def latest(self, name: str) -> tuple[Any, float] | None:
        """The latest ``name`` message from the autopilot's system and its arrival time (:meth:`MavlinkLink.latest`)."""
        return self._link.latest(name)

    @property
    def active(self) -> str:
        """The source whose set-points are forwarded."""
        return self._relay.active

    # ----------------------------------------------------------------- commands (VehicleCommands')
    def arm(self, armed: bool = True, *, force: bool = False, timeout: float = 1.0, retries: int = 3) -> int:
        """Arm (or disarm); the COMMAND_ACK result (:meth:`VehicleCommands.arm`)."""
        return self._commands.arm(armed, force=force, timeout=timeout, retries=retries)

    def set_mode(self, mode: str | int, *, timeout: float = 1.0, retries: int = 3) -> int:
        """Switch ArduSub mode; the COMMAND_ACK result (:meth:`VehicleCommands.set_mode`)."""
        return self._commands.set_mode(mode, timeout=timeout, retries=retries)

    def command_long(
        self, command: int, params: Sequence[float] = (), *, timeout: float = 1.0, retries: int = 3
    ) -> int:
        """Send COMMAND_LONG; its final COMMAND_ACK result (:meth:`VehicleCommands.command_long`)."""
        return self._commands.command_long(command, params, timeout=timeout, retries=retries)

    def set_message_interval(self, msg_id: int, rate_hz: float, *, timeout: float = 1.0, retries: int = 3) -> int:
        """Ask for a message at a rate; the COMMAND_ACK result (:meth:`VehicleCommands.set_message_interval`)."""
        return self._commands.set_message_interval(msg_id, rate_hz, timeout=timeout, retries=retries)

    def request_data_stream(self, stream_id: int, rate_hz: int, start: bool = True) -> None:
        """Start (or stop) a MAV_DATA_STREAM group (:meth:`VehicleCommands.request_data_stream`)."""
        self._commands.request_data_stream(stream_id, rate_hz, start)

    def request_parameter(self, name: str) -> None:
        """Ask for one parameter's value (:meth:`VehicleCommands.request_parameter`)."""
        self._commands.request_parameter(name)

    @property
    def signing_key(self) -> bytes | None:
        """The MAVLink 2 signing key (None: not signing)."""
        return self._link.signing_key

    def setup_signing(self) -> None:
        """Give the vehicle our signing key (:meth:`VehicleCommands.setup_signing`)."""
        self._commands.setup_signing()

    def accepts_unsigned(self, timeout: float = 1.0) -> bool:
        """Whether the vehicle answers unsigned commands on this link (:meth:`VehicleCommands.accepts_unsigned`)."""
        return self._commands.accepts_unsigned(timeout)

    @property
    def accept_unsigned(self) -> bool:
        """With a signing key: whether unsigned frames from the vehicle are taken (until it holds the key)."""
        return self._link.accept_unsigned

    @accept_unsigned.setter
    def accept_unsigned(self, accept: bool) -> None:
        self._link.accept_unsigned = bool(accept)

    def set_parameter(self, name: str, value: float) -> None:
        """Set one parameter (:meth:`VehicleCommands.set_parameter`)."""
        self._commands.set_parameter(name, value)

    def put_file(self, data: bytes, remote: str, *, timeout: float = 10.0, make_directory: bool = False) -> None:
        """Write a file on the vehicle with MAVLink FTP (:meth:`VehicleCommands.put_file`)."""
        self._commands.put_file(data, remote, timeout=timeout, make_directory=make_directory)

    def upload_mission(
        self,
        items: Iterable[MissionItem | Any],
        *,
        mission_type: int = mavlink2.MAV_MISSION_TYPE_MISSION,
        timeout: float = 1.5,
        retries: int = 5,
    ) -> int:
        """Upload a mission; the MAV_MISSION_RESULT (:meth:`VehicleCommands.upload_mission`)."""
        return self._commands.upload_mission(items, mission_type=mission_type, timeout=timeout, retries=retries)
