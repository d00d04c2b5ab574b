"""MAVLink frames as bytes: resynchronising after junk, stripping signatures."""

from __future__ import annotations

from bridge.frames import FrameSplitter, is_signed, mavlink2, strip_signature
from tests.support.bridge_rig import KEY


def test_splitter_resynchronises_after_junk():
    mav = mavlink2.MAVLink(None, 1, 1)
    frames = [mavlink2.MAVLink_system_time_message(i, i).pack(mav) for i in range(3)]
    decoder = mavlink2.MAVLink(None, 2, 2)
    splitter = FrameSplitter(decoder.decode)
    corrupt = bytearray(frames[1])
    corrupt[12] ^= 0xFF
    # junk that claims a long frame (0xFD, len 255) must not swallow the real frames behind it
    stream = b"\x01\x02" + frames[0] + bytes(corrupt) + b"\xfd\xff\x00" + frames[2]
    got = splitter.feed(stream)
    got += splitter.resync()
    assert [m.time_boot_ms for _, m in got] == [0, 2]
    assert splitter.bad_frames >= 2 and splitter.pending == 0


def test_strip_signature_gives_a_valid_unsigned_frame():
    signer = mavlink2.MAVLink(None, 1, 1)
    signer.signing.secret_key = KEY
    signer.signing.sign_outgoing = True
    signer.signing.timestamp = 1
    frame = mavlink2.MAVLink_system_time_message(123, 456).pack(signer)
    assert is_signed(frame)
    stripped = strip_signature(frame)
    assert len(stripped) == len(frame) - 13 and not is_signed(stripped)
    msg = mavlink2.MAVLink(None, 2, 2).decode(bytearray(stripped))  # checks the recomputed CRC
    assert (msg.time_unix_usec, msg.time_boot_ms) == (123, 456)
    assert KEY not in stripped
