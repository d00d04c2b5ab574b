"""An operator's commands to the autopilot over the link: COMMAND_LONG, modes, stream rates, mission upload.

Every command runs under the same gates as a set-point (``allow_commands``, an autopilot heard
within ``silence_s``); each call checks its arguments and the gates before anything is sent,
so nothing but HEARTBEAT reaches a vehicle otherwise. :meth:`VehicleCommands.command_long`
(and ``set_mode``, ``arm``, ``set_message_interval`` on top of it) waits for the final
COMMAND_ACK, :meth:`~VehicleCommands.request_data_stream` sets a stream group's rate and
:meth:`~VehicleCommands.upload_mission` runs :mod:`bridge.mission_upload`'s protocol.

The link's reader hands the replies to a :class:`ReplyMailbox` (COMMAND_ACK to a waiting
command, MISSION_REQUEST(_INT) and MISSION_ACK to the running upload); the commands wait on
the mailbox, never on the link's internals. :class:`Autopilot` reads the autopilot's latest
HEARTBEAT, with its mode named by :data:`ARDUSUB_MODES`.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from rapt.errors import InputError, LinkError, LinkTimeoutError, RefusedError, RunError

from .command_gate import CommandGate
from .frames import mavlink2
from .link import POLL_S, MavlinkLink
from .mission_upload import COUNT, MissionItem, MissionUpload, describe, mission_items

__all__ = ["ARDUSUB_MODES", "Autopilot", "ReplyMailbox", "VehicleCommands", "mode_number"]

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

_MISSION_REPLIES = frozenset(("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"))
_FILE_REPLIES = frozenset(("FILE_TRANSFER_PROTOCOL",))
_REPLIES = _MISSION_REPLIES | _FILE_REPLIES | {"COMMAND_ACK"}  # the messages a waiting command or upload is handed


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


def mode_number(name: str) -> int:
    """The ArduSub mode number of ``name`` (as ``required_mode`` names it)."""
    number = ARDUSUB_MODES.get(str(name).strip().upper())
    if number is None:
        raise InputError(f"required_mode: unknown ArduSub mode {name!r} (known: {', '.join(ARDUSUB_MODES)})")
    return number


def _is_int(value: Any, low: int, high: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and low <= value <= high


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class ReplyMailbox:
    """The replies the link's reader hands over (a :class:`bridge.link.ReplySink`), for the commands waiting on them.

    COMMAND_ACKs are kept per command with a serial number, so a waiter tells an ACK that came
    after its COMMAND_LONG from an older one; mission replies go to the running upload's inbox
    (dropped while no upload runs).
    """

    names = _REPLIES

    def __init__(self) -> None:
        self._acks: dict[int, tuple[int, int, int]] = {}  # command -> (result, progress, serial)
        self._ack_cond = threading.Condition()
        self._ack_serial = 0
        self._mission_inbox: queue.SimpleQueue | None = None  # the running upload's replies, from the reader
        self._file_inbox: queue.SimpleQueue | None = None  # the running file transfer's replies

    def deliver(self, msg: Any) -> None:
        """Called by the reader with a reply from the autopilot addressed to this side."""
        name = msg.get_type()
        if name == "COMMAND_ACK":
            with self._ack_cond:
                self._ack_serial += 1
                self._acks[msg.command] = (msg.result, msg.progress, self._ack_serial)
                self._ack_cond.notify_all()
        elif name in _MISSION_REPLIES or name in _FILE_REPLIES:
            inbox = self._mission_inbox if name in _MISSION_REPLIES else self._file_inbox
            if inbox is not None:
                inbox.put(msg)

    def ack_serial(self) -> int:
        """The serial of the last COMMAND_ACK delivered: an ACK that comes after now has a higher one."""
        with self._ack_cond:
            return self._ack_serial

    def wait_ack(
        self, command: int, after: int, deadline: float, stop: threading.Event, what: str
    ) -> tuple[int, int, int] | None:
        """The first COMMAND_ACK for ``command`` with a serial above ``after`` as (result, progress, serial),
        or None at ``deadline`` (monotonic); LinkError once ``stop`` is set."""
        with self._ack_cond:
            while True:
                ack = self._acks.get(command)
                if ack is not None and ack[2] > after:
                    return ack
                remaining = deadline - time.monotonic()
                if stop.is_set():
                    raise LinkError(f"{what}: the bridge closed while waiting for COMMAND_ACK")
                if remaining <= 0:
                    return None
                self._ack_cond.wait(remaining)

    def open_mission_inbox(self) -> queue.SimpleQueue:
        """An inbox for the mission replies from now on (one upload at a time)."""
        inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._mission_inbox = inbox
        return inbox

    def close_mission_inbox(self) -> None:
        self._mission_inbox = None

    def open_file_inbox(self) -> queue.SimpleQueue:
        """An inbox for the MAVLink FTP replies from now on (one transfer at a time)."""
        inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._file_inbox = inbox
        return inbox

    def close_file_inbox(self) -> None:
        self._file_inbox = None


class VehicleCommands:
    """The commands an operator's bring-up sends the autopilot behind ``link``, under ``gate``'s
    ``allow_commands`` and ``silence_s``; replies come through ``replies``, fed by the link's reader.

    Refusals by ``allow_commands`` are counted in ``counts["commands_refused"]``; ``stop`` (the
    bridge closing) ends a wait with LinkError.
    """

    def __init__(
        self,
        link: MavlinkLink,
        replies: ReplyMailbox,
        gate: CommandGate,
        *,
        counts: dict[str, int],
        stop: threading.Event,
        vehicle: str,
    ):
        self._link = link
        self._replies = replies
        self._gate = gate
        self._counts = counts
        self._stop = stop
        self._vehicle = vehicle  # names the vehicle in the log
        self._mission_lock = threading.Lock()  # one upload at a time

    @property
    def autopilot(self) -> Autopilot | None:
        """The autopilot's latest HEARTBEAT (type, autopilot, base_mode, custom_mode, system_status), or None."""
        latest = self._link.latest("HEARTBEAT")
        if latest is None:
            return None
        msg, at = latest
        return Autopilot(msg.type, msg.autopilot, msg.base_mode, msg.custom_mode, msg.system_status, at)

    # Every command checks its arguments, then the gates (allow_commands, an autopilot heard within
    # silence_s), before anything is sent: nothing but HEARTBEAT reaches a vehicle otherwise.
    def _ready(self, what: str) -> tuple[int, int]:
        """The autopilot's (system, component), once the gates allow a command; otherwise a one-line error."""
        if not self._gate.allow_commands:
            self._counts["commands_refused"] += 1
            raise RefusedError(f"{what}: allow_commands is False, nothing but HEARTBEAT is sent to the vehicle")
        target = self._link.target  # read once: the reader may forget it (link lost) at any time
        if target is None or not self._link.linked:
            raise LinkError(f"{what}: no autopilot heard within the last {self._gate.silence_s} s")
        return target

    def _send_or_raise(self, msg: Any, what: str) -> None:
        if not self._link.send(msg):
            raise LinkError(f"{what}: the link to {self._link.device} closed; nothing was sent")

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
        way ArduPilot and MAVProxy set rates. No reply exists: check the rate in ``latest``."""
        if not _is_int(stream_id, 0, 0xFF):
            raise InputError(f"stream_id: expected a MAV_DATA_STREAM number in 0..255, got {stream_id!r}")
        if not _is_int(rate_hz, 0, 0xFFFF):
            raise InputError(f"rate_hz: expected an int rate in 0..65535 Hz, got {rate_hz!r}")
        if not isinstance(start, bool):
            raise InputError(f"start: expected True (start) or False (stop), got {start!r}")
        target = self._ready("request_data_stream")
        msg = mavlink2.MAVLink_request_data_stream_message(target[0], target[1], stream_id, rate_hz, int(start))
        self._send_or_raise(msg, "request_data_stream")

    def request_parameter(self, name: str) -> None:
        """Ask for parameter ``name`` with PARAM_REQUEST_READ (20); the vehicle's PARAM_VALUE comes as
        telemetry (``latest("PARAM_VALUE")``, and the log). No reply for a name it does not have."""
        if not (isinstance(name, str) and 0 < len(name) <= 16 and name.isascii()):
            raise InputError(f"name: expected a parameter name of 1-16 ASCII characters, got {name!r}")
        target = self._ready("request_parameter")
        msg = mavlink2.MAVLink_param_request_read_message(target[0], target[1], name.encode(), -1)
        self._send_or_raise(msg, "request_parameter")

    def setup_signing(self) -> None:
        """Give the vehicle our signing key with SETUP_SIGNING (256); it signs from then on and refuses unsigned
        messages except on its channel 0. There is no answer: the vehicle's next frames tell."""
        key = self._link.signing_key
        if key is None:
            raise InputError("setup_signing: the bridge has no signing key (--signing-key)")
        target = self._ready("setup_signing")
        msg = mavlink2.MAVLink_setup_signing_message(target[0], target[1], list(key), self._link.signing_timestamp)
        self._send_or_raise(msg, "setup_signing")

    def accepts_unsigned(self, timeout: float = 1.0, tries: int = 2) -> bool:
        """Whether the vehicle answers an unsigned command on this link: REQUEST_MESSAGE(AUTOPILOT_VERSION) sent
        unsigned, its COMMAND_ACK awaited. ArduPilot answers it on its channel 0 whatever its signing says."""
        params = (mavlink2.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
        try:
            self._command_long(
                mavlink2.MAV_CMD_REQUEST_MESSAGE,
                params,
                timeout,
                tries - 1,
                "accepts_unsigned",
                self._link.send_unsigned,
            )
        except LinkTimeoutError:
            return False
        return True

    def set_parameter(self, name: str, value: float) -> None:
        """Set parameter ``name`` with PARAM_SET (23); the vehicle answers with PARAM_VALUE as telemetry
        (``latest("PARAM_VALUE")``): read it back to know it was taken."""
        if not (isinstance(name, str) and 0 < len(name) <= 16 and name.isascii()):
            raise InputError(f"name: expected a parameter name of 1-16 ASCII characters, got {name!r}")
        if not (_is_number(value) and math.isfinite(value)):
            raise InputError(f"value: expected a finite number, got {value!r}")
        target = self._ready("set_parameter")
        msg = mavlink2.MAVLink_param_set_message(
            target[0], target[1], name.encode(), float(value), mavlink2.MAV_PARAM_TYPE_REAL32
        )
        self._send_or_raise(msg, "set_parameter")

    def _command_long(
        self,
        command: int,
        params: Sequence[float],
        timeout: float,
        retries: int,
        what: str,
        send: Callable[[Any], bool] | None = None,
    ) -> int:
        """Send COMMAND_LONG (with ``send``: the link's signed send by default) until its final COMMAND_ACK."""
        if not (_is_number(timeout) and timeout > 0):
            raise InputError(f"timeout: expected a number of seconds > 0, got {timeout!r}")
        if not _is_int(retries, 0, 1000):
            raise InputError(f"retries: expected an int in 0..1000, got {retries!r}")
        target = self._ready(what)
        progress: int | None = None  # set once the vehicle reports MAV_RESULT_IN_PROGRESS
        for attempt in range(retries + 1):
            serial = self._replies.ack_serial()
            msg = mavlink2.MAVLink_command_long_message(target[0], target[1], command, min(attempt, 255), *params)
            (send or self._link.send)(msg)
            deadline = time.monotonic() + timeout
            while (ack := self._replies.wait_ack(command, serial, deadline, self._stop, what)) is not None:
                if ack[0] != mavlink2.MAV_RESULT_IN_PROGRESS:
                    return ack[0]
                # running: sending it again would restart or be refused; wait for the final ACK
                serial, progress = ack[2], ack[1]
                deadline = time.monotonic() + timeout
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
        try:
            # opened before MISSION_COUNT goes out: the first request may come at once
            inbox = self._replies.open_mission_inbox()
            self._send_mission(upload.start(time.monotonic()), checked, target, mission_type)
            while not upload.done:
                if self._stop.is_set():
                    raise LinkError(f"{what}: the bridge closed during the upload ({upload.step})")
                now = time.monotonic()
                if now >= upload.deadline:
                    sends = upload.on_timeout(now)  # raises once the retries are spent
                else:
                    try:
                        msg = inbox.get(timeout=min(upload.deadline - now, POLL_S))
                    except queue.Empty:
                        continue
                    now = time.monotonic()
                    if msg.get_type() == "MISSION_ACK":
                        sends = upload.on_ack(msg.type, msg.mission_type, now)
                        if msg.type != mavlink2.MAV_MISSION_ACCEPTED:
                            log.info("bridge %s: %s NACK %s (%s)", self._vehicle, what, describe(msg.type), upload.step)
                    else:
                        sends = upload.on_request(msg.seq, msg.mission_type, now)
                self._send_mission(sends, checked, target, mission_type)
        finally:
            self._replies.close_mission_inbox()
            self._mission_lock.release()
        assert upload.result is not None, "the loop ends only when the upload is done"
        if upload.result != mavlink2.MAV_MISSION_ACCEPTED:
            log.warning("bridge %s: %s ended with %s", self._vehicle, what, describe(upload.result))
        return upload.result

    # ----------------------------------------------------------------- files
    def put_file(self, data: bytes, remote: str, *, timeout: float = 10.0, make_directory: bool = False) -> None:
        """Write ``data`` to ``remote`` on the vehicle with MAVLink FTP (:mod:`bridge.file_transfer`; with
        ``make_directory`` its missing directory is made); a :class:`~rapt.errors.RefusedError` naming the
        vehicle's FTP error, or LinkTimeoutError."""
        from .file_transfer import put_file

        what = "put_file"
        target = self._ready(what)
        if not self._mission_lock.acquire(blocking=False):
            raise RunError(f"{what}: an upload is running on this bridge; wait for it to end")
        try:
            inbox = self._replies.open_file_inbox()
            put_file(self._link, inbox, target, data, remote, timeout=timeout, make_directory=make_directory)
        finally:
            self._replies.close_file_inbox()
            self._mission_lock.release()

    def _send_mission(self, sends: list[int], items: list[MissionItem], target: tuple[int, int], kind: int) -> None:
        for seq in sends:
            if seq == COUNT:
                msg = mavlink2.MAVLink_mission_count_message(target[0], target[1], len(items), kind)
            else:
                msg = items[seq].to_message(target[0], target[1], kind)
            self._link.send(msg)  # a closed link is a timeout for the upload, as a lost frame is
