"""MAVLink frames as bytes: cut them out of a noisy link, strip signatures, turn them into JSON.

pymavlink's own parser trusts the first magic byte it sees: junk ending in ``0xFD 0xFF``
swallows the next real frames, and a datagram's leftovers corrupt the next datagram. The
:class:`FrameSplitter` here resynchronises one byte after a frame that does not decode, ends
each UDP datagram cleanly, and counts what it throws away instead of raising.
"""

from __future__ import annotations

import base64
import json
import math
import os
import re
import struct
from collections.abc import Callable
from typing import Any

os.environ.setdefault("MAVLINK20", "1")

from pymavlink.dialects.v20 import ardupilotmega as mavlink2  # noqa: E402
from pymavlink.generator.mavcrc import x25crc  # noqa: E402

from rapt.errors import InputError  # noqa: E402

__all__ = ["mavlink2", "FrameSplitter", "strip_signature", "is_signed", "message_json"]

_MAGIC = re.compile(b"[\xfd\xfe]")
_V2 = mavlink2.PROTOCOL_MARKER_V2
_SIGNED = mavlink2.MAVLINK_IFLAG_SIGNED
_SIG_LEN = mavlink2.MAVLINK_SIGNATURE_BLOCK_LEN


def _frame_length(buf: bytearray, i: int) -> int | None:
    """Length of the frame starting at ``buf[i]``; None if the header is incomplete, 0 if invalid."""
    if len(buf) - i < 3:
        return None
    plen = buf[i + 1]
    if buf[i] == _V2:
        flags = buf[i + 2]
        if flags & ~_SIGNED:
            return 0
        return 12 + plen + (_SIG_LEN if flags & _SIGNED else 0)
    return 8 + plen


class FrameSplitter:
    """Split received bytes into ``(frame_bytes, message)`` pairs.

    ``decode`` is a ``pymavlink`` ``MAVLink.decode`` (it checks CRC and signatures). Counters:
    ``bad_frames`` (runs of bytes that did not decode: junk, bad CRC, truncation, unknown
    message ids), ``bad_bytes``, ``unsigned`` and ``bad_signature`` (CRC-valid frames refused
    by signing).
    """

    def __init__(self, decode: Callable[[bytearray], Any]):
        self._decode = decode
        self._buf = bytearray()
        self._junk = 0
        self.bad_frames = 0
        self.bad_bytes = 0
        self.unsigned = 0
        self.bad_signature = 0

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def feed(self, data: bytes, *, datagram: bool = False) -> list[tuple[bytes, Any]]:
        """Add received bytes; with ``datagram=True`` nothing is carried over to the next call."""
        self._buf += data
        out = self._parse()
        if datagram:
            self._junk += len(self._buf)
            self._buf.clear()
            self._end_junk()
        return out

    def resync(self) -> list[tuple[bytes, Any]]:
        """The link went quiet with a partial frame held back: treat it as junk, keep what follows."""
        out: list[tuple[bytes, Any]] = []
        while self._buf:
            del self._buf[:1]
            self._junk += 1
            out += self._parse()
        self._end_junk()
        return out

    def reset(self) -> None:
        """Forget held-back bytes (a new connection starts a new stream)."""
        self._junk += len(self._buf)
        self._buf.clear()
        self._end_junk()

    def _end_junk(self) -> None:
        if self._junk:
            self.bad_frames += 1
            self.bad_bytes += self._junk
            self._junk = 0

    def _parse(self) -> list[tuple[bytes, Any]]:
        buf, out, i, n = self._buf, [], 0, len(self._buf)
        while i < n:
            match = _MAGIC.search(buf, i)
            if match is None:
                self._junk += n - i
                i = n
                break
            j = match.start()
            self._junk += j - i
            i = j
            length = _frame_length(buf, i)
            if length is None or (length and n - i < length):
                break  # wait for the rest
            if length == 0:
                self._junk += 1
                i += 1
                continue
            frame = bytes(buf[i : i + length])
            try:
                msg = self._decode(bytearray(frame))
            except Exception as error:  # MAVError, and anything a corrupted payload provokes
                if str(error) == "Invalid signature":
                    self._end_junk()
                    if frame[0] == _V2 and frame[2] & _SIGNED:
                        self.bad_signature += 1
                    else:
                        self.unsigned += 1
                    i += length
                else:
                    self._junk += 1
                    i += 1
                continue
            if isinstance(msg, mavlink2.MAVLink_unknown):
                self._junk += 1  # the CRC of an unknown message cannot be checked
                i += 1
                continue
            self._end_junk()
            out.append((frame, msg))
            i += length
        del buf[:i]
        return out


def message_id(frame: bytes) -> int | None:
    """The message id in a frame's header (MAVLink 2 or 1), None when it is not a frame's start.

    Lets a reader skip the messages it has no use for without decoding them.
    """
    if len(frame) >= 10 and frame[0] == _V2:
        return frame[7] | frame[8] << 8 | frame[9] << 16
    if len(frame) >= 6 and frame[0] == 0xFE:
        return frame[5]
    return None


def is_signed(frame: bytes) -> bool:
    """True for a MAVLink2 frame carrying a signature block."""
    return len(frame) > 2 and frame[0] == _V2 and bool(frame[2] & _SIGNED)


def strip_signature(frame: bytes) -> bytes:
    """The frame without its 13-byte signature block, incompat flag 0x01 cleared, CRC recomputed.

    The MAVLink2 CRC covers the incompat flags, so the CRC is recomputed with the message's
    CRC_EXTRA (ardupilotmega dialect) and the stripped frame stays valid unsigned MAVLink2.
    Frames that are not signed are returned unchanged.
    """
    frame = bytes(frame)
    if not is_signed(frame):
        return frame
    end = 10 + frame[1]
    if len(frame) != end + 2 + _SIG_LEN:
        raise InputError(f"frame: signed frame of {len(frame)} bytes, expected {end + 2 + _SIG_LEN}")
    body = bytearray(frame[:end])
    body[2] &= ~_SIGNED & 0xFF
    msg_id = body[7] | (body[8] << 8) | (body[9] << 16)
    cls = mavlink2.mavlink_map.get(msg_id)
    if cls is None:  # cannot recompute: keep the old CRC, still drop the signature
        return bytes(body) + frame[end : end + 2]
    crc = x25crc(bytes(body[1:]) + bytes([cls.crc_extra])).crc
    return bytes(body) + struct.pack("<H", crc)


def _clean(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, (bytes, bytearray)):
        return base64.b64encode(value).decode("ascii")
    if isinstance(value, list):
        return [_clean(v) for v in value]
    return value


def _not_plain(value: Any) -> Any:
    raise TypeError("not plain JSON")


# json.dumps builds an encoder on every call; a bridge at 20,000 frames/s cannot afford that.
# Arguments: markers, default, encoder, indent, key and item separators, sort_keys, skipkeys, allow_nan.
_make_encoder: Any = getattr(json.encoder, "c_make_encoder", None)
_plain_json = (
    None
    if _make_encoder is None
    else _make_encoder(None, _not_plain, json.encoder.encode_basestring_ascii, None, ":", ",", False, False, False)
)


def message_json(msg: Any, recv_ns: int) -> bytes:
    """``msg.to_dict()`` as strict JSON (bytes base64, NaN/inf null) plus ``"_recv_ns"``."""
    d = msg.to_dict()
    d["_recv_ns"] = int(recv_ns)
    if _plain_json is not None:
        try:  # the common case: numbers and text only, all finite
            return "".join(_plain_json(d, 0)).encode()
        except (TypeError, ValueError):  # bytes, NaN or inf somewhere: clean them first
            pass
    d = {k: _clean(v) for k, v in d.items()}
    return json.dumps(d, separators=(",", ":"), allow_nan=False).encode()
