"""The parameter file over MAVLink FTP, as ArduPilot packs it: a client reads it back to the table."""

from __future__ import annotations

import struct

from sim.uuv.ardusub.ftp import ACK, BURST_READ, NAK, OPEN_RO, READ, ParamFileServer
from sim.uuv.ardusub.params import ParameterTable

TYPES = {1: "<b", 2: "<h", 3: "<i", 4: "<f"}


def request(seq: int, opcode: int, data: bytes = b"", offset: int = 0, size: int | None = None) -> bytes:
    size = len(data) if size is None else size
    return struct.pack("<HBBBBBBI", seq, 0, opcode, size, 0, 0, 0, offset) + data


def header(reply: bytes) -> tuple:
    return struct.unpack("<HBBBBBBI", reply[:12])


def decode(blob: bytes) -> tuple[dict, dict]:
    """(values, defaults) by name, reading the format independently of the server."""
    magic, count, total = struct.unpack("<HHH", blob[:6])
    assert magic in (0x671B, 0x671C) and count == total
    values, defaults, last, i = {}, {}, b"", 6
    while i < len(blob):
        kind, lengths = blob[i], blob[i + 1]
        common, rest = lengths & 0x0F, (lengths >> 4) + 1
        name = last[:common] + blob[i + 2 : i + 2 + rest]
        fmt = TYPES[kind & 0x0F]
        i += 2 + rest
        (values[name.decode()],) = struct.unpack_from(fmt, blob, i)
        i += struct.calcsize(fmt)
        if kind & 0x10:
            (defaults[name.decode()],) = struct.unpack_from(fmt, blob, i)
            i += struct.calcsize(fmt)
        last = name
    assert len(values) == total
    return values, defaults


def download(server: ParamFileServer, path: bytes) -> bytes:
    (opened,) = server.answer(request(1, OPEN_RO, path))
    _, _, code, size, req, _, _, _ = header(opened)
    assert (code, req, size) == (ACK, OPEN_RO, 4)
    (length,) = struct.unpack("<I", opened[12:16])
    blob, seq = b"", 2
    while True:
        replies = server.answer(request(seq, BURST_READ, offset=len(blob), size=239))
        seq += 1
        for reply in replies:
            _, _, code, size, _, last, _, offset = header(reply)
            if code == NAK:
                assert reply[12] == 6  # end of file
                assert len(blob) == length
                return blob
            assert offset == len(blob) and size <= 239
            blob += reply[12 : 12 + size]


def test_the_parameter_file_reads_back_to_the_table_with_its_defaults():
    params = ParameterTable({"WPNAV_SPEED": 150.0})
    params.set("FS_GCS_ENABLE", 0)
    server = ParamFileServer(params)
    values, defaults = decode(download(server, b"@PARAM/param.pck"))
    assert list(values) == params.names
    assert all(abs(values[n] - params[n]) < 1e-6 for n in params.names)
    assert defaults == {}
    values, defaults = decode(download(server, b"@PARAM/param.pck?withdefaults=1"))
    assert defaults == {"WPNAV_SPEED": 100.0, "FS_GCS_ENABLE": 2}  # only where the value is not ArduSub's default


def test_what_is_not_served_gets_the_nak_ardupilot_gives():
    server = ParamFileServer(ParameterTable())
    (reply,) = server.answer(request(1, OPEN_RO, b"@SYS/threads.txt"))
    assert header(reply)[2] == NAK and reply[12] == 10  # file not found
    (reply,) = server.answer(request(2, READ, offset=0, size=10))
    assert header(reply)[2] == NAK and reply[12] == 1  # no file open
    (reply,) = server.answer(request(3, 3, b"/"))  # ListDirectory
    assert header(reply)[2] == NAK and reply[12] == 7  # unknown command
    download(server, b"@PARAM/param.pck")
    (reply,) = server.answer(request(9, READ, offset=100000, size=10))
    assert header(reply)[2] == NAK and reply[12] == 6  # end of file
