"""MAVLink FTP, as much of it as a ground station uses on ArduSub: the parameter file ``@PARAM/param.pck``.

MAVProxy and QGroundControl fetch an ArduPilot vehicle's parameters over MAVLink FTP
(FILE_TRANSFER_PROTOCOL) before falling back to PARAM_REQUEST_LIST.  This serves that file
as ArduPilot packs it (AP_Filesystem_Param): a header ``<HHH`` (magic 0x671B, or 0x671C with
defaults; parameter count twice), then per parameter a type byte (1 int8, 2 int16, 3 int32,
4 float; flag 0x10 when a default follows), a byte with the length of the name prefix shared
with the previous name (low nibble) and of the rest minus one (high nibble), the rest of
the name, the value (and its default).  Opcodes: TerminateSession, ResetSessions,
OpenFileRO, ReadFile, BurstReadFile; any other path or opcode gets a NAK (FileNotFound,
UnknownCommand), EOF a NAK EndOfFile, as ArduPilot's AP_MAVLinkFTP answers.
"""

from __future__ import annotations

import struct

from sim.uuv.ardusub.params import ARDUSUB_PARAMETERS, INT8, INT16, INT32, REAL32, ParameterTable

__all__ = ["ParamFileServer", "param_pck"]

TERMINATE, RESET, OPEN_RO, READ, BURST_READ = 1, 2, 4, 5, 15
ACK, NAK = 128, 129
ERR_FAIL, ERR_EOF, ERR_UNKNOWN_COMMAND, ERR_FILE_NOT_FOUND = 1, 6, 7, 10
#: Data bytes in one FILE_TRANSFER_PROTOCOL payload (251 minus the 12-byte header).
MAX_DATA = 239
PARAM_FILE = "@PARAM/param.pck"
_PACK = {INT8: (1, "<b"), INT16: (2, "<h"), INT32: (3, "<i"), REAL32: (4, "<f")}


def param_pck(params: ParameterTable, with_defaults: bool = False) -> bytes:
    """The parameter file ArduPilot serves as ``@PARAM/param.pck`` (``?withdefaults=1``: with defaults)."""
    defaults = {name: value for name, value, _ in ARDUSUB_PARAMETERS}
    out = bytearray(struct.pack("<HHH", 0x671C if with_defaults else 0x671B, len(params), len(params)))
    last = b""
    for name in params.names:
        key = name.encode()
        common = 0
        while common < min(len(last), len(key) - 1, 15) and last[common] == key[common]:
            common += 1
        kind, fmt = _PACK[params.types[name]]
        value = params[name]
        default = defaults[name]
        has_default = with_defaults and value != default
        out += bytes([kind | (0x10 if has_default else 0), common | ((len(key) - common - 1) << 4)])
        out += key[common:]
        out += struct.pack(fmt, value if fmt == "<f" else int(value))
        if has_default:
            out += struct.pack(fmt, default if fmt == "<f" else int(default))
        last = key
    return bytes(out)


class ParamFileServer:
    """Answers FILE_TRANSFER_PROTOCOL payloads; one session, the parameter file only."""

    def __init__(self, params: ParameterTable):
        self.params = params
        self.file: bytes | None = None

    def answer(self, request: bytes) -> list[bytes]:
        """The reply payloads (251 bytes each) to one request payload, in order."""
        if len(request) < 12:
            return []
        seq, session, opcode, size, _, _, _, offset = struct.unpack("<HBBBBBBI", bytes(request[:12]))
        data = bytes(request[12 : 12 + size])

        def reply(code: int, body: bytes = b"", at: int = 0, last: bool = False) -> bytes:
            head = struct.pack("<HBBBBBBI", (seq + 1) & 0xFFFF, session, code, len(body), opcode, int(last), 0, at)
            return (head + body).ljust(251, b"\0")

        if opcode in (TERMINATE, RESET):
            self.file = None
            return [reply(ACK)]
        if opcode == OPEN_RO:
            path, _, query = data.split(b"\0")[0].decode(errors="replace").partition("?")
            if path != PARAM_FILE:
                return [reply(NAK, bytes([ERR_FILE_NOT_FOUND]))]
            self.file = param_pck(self.params, with_defaults="withdefaults=1" in query)
            return [reply(ACK, struct.pack("<I", len(self.file)))]
        if opcode in (READ, BURST_READ):
            if self.file is None:
                return [reply(NAK, bytes([ERR_FAIL]))]
            if offset >= len(self.file):
                return [reply(NAK, bytes([ERR_EOF]), offset)]
            if opcode == READ:
                return [reply(ACK, self.file[offset : offset + min(size or MAX_DATA, MAX_DATA)], offset)]
            chunk = min(size or MAX_DATA, MAX_DATA)
            starts = range(offset, len(self.file), chunk)
            return [reply(ACK, self.file[s : s + chunk], s, last=s + chunk >= len(self.file)) for s in starts]
        return [reply(NAK, bytes([ERR_UNKNOWN_COMMAND]))]
