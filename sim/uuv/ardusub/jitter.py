"""Report timing of a vehicle behind a radio link or on a busy autopilot: jittered and dropped reports.

ArduSub streams each message on its own schedule (:mod:`sim.uuv.ardusub.streams`), but what a
back-seat receives from a real vehicle does not keep that cadence: a busy autopilot sends a
report late or early by a scheduler slot, a radio link holds one back and loses another.
:class:`JitteredSchedule` wraps the bare front-seat's schedule so that each position and
attitude report (:data:`JITTERED`) goes out at its nominal time plus a seeded uniform draw
in ±``jitter_s``, stamped with the vehicle time it is actually sent at (its
``time_boot_ms`` is true: the state it carries is the state at that instant), and a seeded
share ``drop`` of them is never sent.  Every other message keeps its nominal time.  Rate
changes (SET_MESSAGE_INTERVAL, REQUEST_DATA_STREAM) still go to the wrapped schedule, so the
vehicle answers them as before.

Reports are taken from the wrapped schedule ``jitter_s`` ahead of their nominal time (so a
report may go out early), one nominal instant at a time (so the schedule keeps its cadence).
Two draws are made per report, whether or not it is dropped, so one seed gives the same
timing with and without drops.
"""

from __future__ import annotations

import heapq
import math

import numpy as np

from rapt.errors import InputError
from sim.uuv.ardusub.streams import StreamSchedule

__all__ = ["JitteredSchedule", "JITTERED", "check_report_timing"]

#: The reports whose timing is disturbed: position (as the back-seat reads it) and attitude.
JITTERED = frozenset({"GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "ATTITUDE"})


def check_report_timing(jitter_s: float, drop: float) -> None:
    """A one-line InputError for a jitter that is not a finite number of seconds >= 0, or a drop share outside [0, 1)."""
    if not (math.isfinite(jitter_s) and jitter_s >= 0):
        raise InputError(f"jitter: expected vehicle seconds >= 0 (e.g. 0.25), got {jitter_s}")
    if not (math.isfinite(drop) and 0 <= drop < 1):
        raise InputError(f"drop_reports: expected a share of reports in [0, 1) (e.g. 0.1), got {drop}")


class JitteredSchedule:
    """``inner``'s messages, the :data:`JITTERED` ones moved by ±``jitter_s`` and a share ``drop`` lost (module docstring).

    Offers what the bare autopilot's loop reads of a schedule: :meth:`next_time` and :meth:`due`.
    """

    def __init__(self, inner: StreamSchedule, jitter_s: float, drop: float, seed: int):
        check_report_timing(jitter_s, drop)
        self.inner, self.jitter_s, self.drop = inner, float(jitter_s), float(drop)
        self.rng = np.random.default_rng(seed)
        self.pending: list[tuple[float, int, str]] = []  # (send time, order, message): a heap
        self._order = 0
        self.sent = 0  # disturbed reports sent and dropped, for a test's account
        self.dropped = 0

    def next_time(self) -> float:
        """The next vehicle time the loop must stop at: a report to send, or one to take from ``inner``."""
        ahead = self.inner.next_time() - self.jitter_s
        return min(ahead, self.pending[0][0]) if self.pending else ahead

    def due(self, now: float) -> list[str]:
        """The messages to send at vehicle time ``now``, in the order their send times fall."""
        self._take(now)
        out = []
        while self.pending and self.pending[0][0] <= now + 1e-9:
            out.append(heapq.heappop(self.pending)[2])
        return out

    def _take(self, now: float) -> None:
        """Every message ``inner`` has due up to ``now + jitter_s``, queued at its send time (never before ``now``)."""
        horizon = now + self.jitter_s + 1e-9
        while (when := self.inner.next_time()) <= horizon:
            for name in self.inner.due(when):
                at = when
                if name in JITTERED:
                    shift, lost = self.rng.uniform(-self.jitter_s, self.jitter_s), self.rng.random() < self.drop
                    if lost:
                        self.dropped += 1
                        continue
                    self.sent += 1
                    at = when + shift
                heapq.heappush(self.pending, (max(at, now), self._order, name))
                self._order += 1
