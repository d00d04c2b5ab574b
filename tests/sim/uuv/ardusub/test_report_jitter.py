"""The bare front-seat's report jitter and drops (sim.uuv.ardusub.jitter), driven as its loop drives a schedule."""

from __future__ import annotations

import numpy as np
import pytest

from rapt.errors import InputError
from sim.uuv.ardusub.jitter import JITTERED, JitteredSchedule
from sim.uuv.ardusub.streams import StreamSchedule

SPAN_S = 120.0


def _sent(schedule, span: float = SPAN_S) -> list[tuple[float, str]]:
    """(vehicle time, message) of everything sent over ``span`` s, advancing to each next event as the bare loop does."""
    t, out = 0.0, []
    while t <= span:
        out += [(t, name) for name in schedule.due(t)]
        t = max(t, schedule.next_time())
    return out


def test_reports_move_within_the_jitter_others_keep_their_cadence_and_a_share_is_lost():
    plain = _sent(StreamSchedule())
    jittered = JitteredSchedule(StreamSchedule(), 0.25, 0.1, seed=4)
    sent = _sent(jittered)
    others = [(t, n) for t, n in plain if n not in JITTERED and t <= SPAN_S - 0.25]
    assert others and set(others) <= set(sent)  # BATTERY_STATUS, SYSTEM_TIME, ... as before, to the instant
    assert [t for t, _ in sent] == sorted(t for t, _ in sent)
    for name in JITTERED:
        nominal = np.array([t for t, n in plain if n == name])
        times = np.array([t for t, n in sent if n == name and 1.0 <= t <= SPAN_S - 1.0])
        nearest = nominal[np.abs(nominal[None, :] - times[:, None]).argmin(axis=1)]
        offset = times - nearest
        assert np.all(np.abs(offset) <= 0.25 + 1e-9), name
        period = nominal[1] - nominal[0]
        if period > 0.5:  # a slow stream: each report is near its own slot, spread over the whole ±0.25 s
            assert offset.min() < -0.2 and offset.max() > 0.2, name
    assert jittered.dropped / (jittered.sent + jittered.dropped) == pytest.approx(0.1, abs=0.02)
    # one seed, one timing; the same draws with and without drops
    assert _sent(JitteredSchedule(StreamSchedule(), 0.25, 0.1, seed=4)) == sent
    kept = set(_sent(JitteredSchedule(StreamSchedule(), 0.25, 0.0, seed=4)))
    assert set(sent) <= kept and len(kept) > len(sent)


def test_a_slow_report_stream_jitters_around_each_slot():
    inner = StreamSchedule()
    inner.override = {name: 0.5 for name in JITTERED}  # one report every 2 s: each draw is its own
    sent = _sent(JitteredSchedule(inner, 0.25, 0.0, seed=1))
    times = np.array([t for t, n in sent if n == "GLOBAL_POSITION_INT" and t > 1.0])
    offset = times - np.round(times / 2.0) * 2.0
    assert np.all(np.abs(offset) <= 0.25 + 1e-9) and offset.std() > 0.1
    assert len(times) == pytest.approx(SPAN_S / 2.0 - 1, abs=1)


@pytest.mark.parametrize(
    ("jitter", "drop", "expect"),
    [(-0.1, 0.0, "jitter: expected vehicle seconds >= 0"), (0.1, 1.0, "drop_reports: expected a share")],
)
def test_bad_timing_is_a_one_line_error_naming_the_field(jitter, drop, expect):
    with pytest.raises(InputError, match=expect):
        JitteredSchedule(StreamSchedule(), jitter, drop, seed=0)
