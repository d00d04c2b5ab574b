"""Counting what went missing on the way from a vehicle to the log, instead of losing it silently.

Three places can lose a frame, and each has its own counter:

* the MAVLink link (radio, UDP socket, serial port): every sender numbers its frames modulo 256
  per (system id, component id), so :class:`SequenceGaps` counts the numbers that never came,
  as QGroundControl and pymavlink's ``mavloss`` do (a single per-link counter would over-count
  when several components share a link). :func:`udp_drops` reads the kernel's own count of
  datagrams a UDP socket's receive buffer had no room for (Linux).
* the bus between the bridge and the logger: the bridge numbers what it publishes on each key
  (:func:`bridge.keys.sequence_attachment`) and :class:`PublicationGaps` counts the numbers the
  logger never received.
* the logger's writer: the logger counts what it could not write.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["SequenceGaps", "PublicationGaps", "frame_source_seq", "udp_drops"]


def frame_source_seq(frame: bytes) -> tuple[int, int, int]:
    """``(system id, component id, sequence)`` from a MAVLink 2 or 1 frame's header."""
    if frame[0] == 0xFD:
        return frame[5], frame[6], frame[4]
    return frame[3], frame[4], frame[2]


class SequenceGaps:
    """MAVLink sequence numbers that never arrived, per sender ``(system, component)``.

    A number ahead of the expected one counts the numbers skipped as lost (a gap of 128 or
    more is read as a loss too: under load whole bursts go, and a modulo-256 counter cannot
    tell them from anything else). A number that was counted lost and then arrives is a late
    (reordered) frame: it is taken back off ``lost``. The last number again is a duplicate.
    A sender's first frame only sets where its sequence starts.
    """

    def __init__(self) -> None:
        self._last: dict[tuple[int, int], int] = {}
        self._missing: dict[tuple[int, int], set[int]] = {}
        self.lost = 0
        self.by_source: dict[tuple[int, int], int] = {}
        self.late = 0
        self.duplicates = 0

    def see(self, system: int, component: int, seq: int) -> None:
        source = (system, component)
        last = self._last.get(source)
        if last is None:
            self._last[source] = seq
            self._missing[source] = set()
            self.by_source[source] = 0
            return
        gap = (seq - last - 1) & 0xFF
        missing = self._missing[source]
        if gap == 0:
            self._last[source] = seq
            if missing:
                missing.discard(seq)  # a stale entry from the previous turn of the counter
        elif seq in missing:
            missing.discard(seq)
            self.lost -= 1
            self.by_source[source] -= 1
            self.late += 1
        elif gap == 0xFF:
            self.duplicates += 1
        else:
            self.lost += gap
            self.by_source[source] += gap
            missing.discard(seq)
            missing.update((last + 1 + k) & 0xFF for k in range(gap))
            self._last[source] = seq

    def as_dict(self) -> dict:
        """``{"lost", "late", "duplicates", "by_source": {"sys/comp": lost}}`` (JSON-ready)."""
        return {
            "lost": self.lost,
            "late": self.late,
            "duplicates": self.duplicates,
            "by_source": {f"{s}/{c}": n for (s, c), n in sorted(self.by_source.items())},
        }


class PublicationGaps:
    """Publications a subscriber never received, per key, from the publisher's running counter.

    A key's first number only sets the start (the subscriber may have joined late). A number
    below the expected one means the publisher started again (its counter restarted): a new
    start, counted in ``restarts``.
    """

    def __init__(self) -> None:
        self._next: dict[str, int] = {}
        self.lost = 0
        self.by_key: dict[str, int] = {}
        self.restarts = 0

    def see(self, key: str, number: int) -> None:
        expected = self._next.get(key)
        self._next[key] = number + 1
        if expected is None or number == expected:
            return
        if number > expected:
            self.lost += number - expected
            self.by_key[key] = self.by_key.get(key, 0) + number - expected
        else:
            self.restarts += 1


def udp_drops(fd: int) -> int | None:
    """Datagrams the kernel dropped for the UDP socket ``fd`` (its receive buffer was full), or None
    where that is not known (not Linux, not a UDP socket)."""
    try:
        inode = str(os.fstat(fd).st_ino)
    except OSError:
        return None
    for table in ("/proc/net/udp", "/proc/net/udp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 12 and fields[9] == inode:
                return int(fields[-1])
    return None
