"""A file onto the vehicle with MAVLink FTP, through the bridge's own link.

pymavlink's :class:`~pymavlink.mavftp.MAVFTP` is the protocol's client (sessions, sequence
numbers, windowed writes, retries). It expects a pymavlink connection it reads from itself;
the bridge's reader owns the link, so :class:`_LinkPort` gives MAVFTP what it uses of one: a
sender for FILE_TRANSFER_PROTOCOL and the replies the reader hands over (addressed to this side).

ArduSub's FTP server refused the first write of a fresh session with FileNotFound (seen on
the firmware; after a listing the same write is accepted), so a transfer lists the target's
directory first, which also tells a refused write in a missing directory from others.
"""

from __future__ import annotations

import io
import logging
import posixpath
import queue
from typing import Any

from pymavlink.mavftp import MAVFTP, FtpError

from rapt.errors import LinkTimeoutError, RefusedError

from .frames import mavlink2

__all__ = ["put_file"]

log = logging.getLogger(__name__)

#: Seconds without a reply that end a listing (MAVFTP's default, 3.7 s, is a radio link's worst case; a
#: listing of a small directory is one or two replies).
IDLE_S = 0.6
#: FTP errors that mean the link, not the vehicle, failed.
_TIMEOUTS = {FtpError.RemoteReplyTimeout, FtpError.NoSessionsAvailable}


class _LinkPort:
    """What :class:`MAVFTP` uses of a pymavlink connection, over the bridge's link and its reply inbox."""

    def __init__(self, link: Any, inbox: queue.SimpleQueue, target: tuple[int, int]):
        self._link, self._inbox = link, inbox
        self.mav = self
        self.source_system, self.source_component = link.source_system, link.source_component
        self.target_system, self.target_component = target

    def file_transfer_protocol_send(self, network: int, target_system: int, target_component: int, payload) -> None:
        msg = mavlink2.MAVLink_file_transfer_protocol_message(network, target_system, target_component, payload)
        self._link.send(msg)  # a lost frame is retried by MAVFTP as a lost reply is

    def recv_match(self, type=None, blocking: bool = True, timeout: float | None = None, **_: Any):  # noqa: A002
        try:
            return self._inbox.get(timeout=timeout if blocking else 0.0)
        except queue.Empty:
            return None

    def close(self) -> None:
        pass


def put_file(
    link: Any,
    inbox: queue.SimpleQueue,
    target: tuple[int, int],
    data: bytes,
    remote: str,
    *,
    timeout: float = 10.0,
    make_directory: bool = False,
) -> None:
    """Write ``data`` to ``remote`` on the autopilot ``target`` (system, component) behind ``link``, whose FTP
    replies arrive in ``inbox``; with ``make_directory``, a missing directory of ``remote`` is created first (one
    level: its parent must exist). Raises :class:`RefusedError` with the vehicle's FTP error, or
    :class:`LinkTimeoutError` when it does not answer within ``timeout`` seconds."""
    ftp = MAVFTP(_LinkPort(link, inbox, target), target[0], target[1])
    ftp.ftp_settings.read_retry_time = IDLE_S / 2  # below the idle time, as MAVFTP requires
    ftp.ftp_settings.idle_detection_time = IDLE_S
    where = posixpath.dirname(remote) or "."
    ftp.cmd_list([where])  # the session's first request: see the module docstring
    listed = ftp.process_ftp_reply("ListDirectory", timeout=timeout)
    if listed.error_code in _TIMEOUTS:
        raise LinkTimeoutError(f"MAVLink FTP: no answer from the vehicle within {timeout:g} s; does it offer FTP?")
    there = bool(getattr(ftp, "list_result", None))
    if make_directory and listed.error_code != FtpError.Success:
        made = ftp.cmd_mkdir([where])
        there = made.error_code == FtpError.Success
        if there:
            log.info("MAVLink FTP: made the directory %s", where)
    put = ftp.cmd_put(["-", remote], fh=io.BytesIO(data), callback=lambda _fh: None)
    if put.error_code == FtpError.Success:
        put = ftp.process_ftp_reply("put", timeout=timeout)  # "put": MAVFTP ends an upload on its last reply
    if put.error_code in _TIMEOUTS:
        raise LinkTimeoutError(f"MAVLink FTP: writing {remote!r}: no answer within {timeout:g} s")
    if put.error_code != FtpError.Success:
        missing = "" if there else f"; is there a directory {where!r} on the vehicle?"
        raise RefusedError(f"MAVLink FTP: the vehicle refused to write {remote!r} ({_name(put.error_code)}){missing}")
    log.info("MAVLink FTP: %d bytes to %s", len(data), remote)


def _name(code: int) -> str:
    try:
        return FtpError(code).name
    except ValueError:
        return f"error {code}"
