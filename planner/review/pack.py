"""The vehicle's own pack, read from its logs: how much energy it holds down to the watchdog's limit.

A scenario's fuel is virtual (the live-virtual range's gauge counts the vehicle's real draw
against the scenario's starting charge of the mission's ``battery_wh``), but the vehicle's
real pack ends a run too: the watchdog surfaces the vehicle when the pack's own
``BATTERY_STATUS`` (id 0) reports :data:`PACK_CRITICAL_PERCENT` or less.  A plan that gives
the virtual gauge more energy than the pack holds predicts outcomes the vehicle never
reaches (on ArduSub SITL with an 18 Ah pack most 45-minute scenarios ended this way where
the plan predicted success).  So calibration reads the pack's size from what the logs show:
the charge it reports remaining against the energy it reports drawn (ArduPilot counts
``battery_remaining`` down from ``BATT_CAPACITY`` by the charge drawn), fitted by least
squares over every report, and the energy a full pack holds down to the limit (a range
charges the pack before each run; the charge a log happens to start at is recorded too).
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError

from bridge import keys
from bridge.logger import read_log
from sim.uuv.interface import HJ_PER_WH

__all__ = ["PackReading", "read_pack", "PACK_CRITICAL_PERCENT", "MIN_SPAN_PERCENT"]

#: The watchdog's default limit on the vehicle's real pack (planner.fly.vehicle.watchdog.WatchdogRules).
PACK_CRITICAL_PERCENT = 10.0
#: Fewest percentage points the reported charge must fall over the logs for its size to be read.
MIN_SPAN_PERCENT = 5.0


@dataclass(frozen=True)
class PackReading:
    """The pack as the logs show it: its full capacity, the charge at the start and the energy to the limit."""

    capacity_wh: float  # energy of a full pack (Wh)
    start_percent: float  # charge reported when the first log starts
    usable_wh: float  # energy of a full pack down to the watchdog's limit (Wh)
    reports: int  # BATTERY_STATUS reports of the pack the fit used
    span_percent: float  # how far the reported charge fell over the logs

    def to_dict(self) -> dict:
        return {
            "capacity_wh": self.capacity_wh,
            "start_percent": self.start_percent,
            "usable_wh": self.usable_wh,
            "critical_percent": PACK_CRITICAL_PERCENT,
            "reports": self.reports,
            "span_percent": self.span_percent,
        }


def _pack_reports(path: Path, vehicle: str) -> list[tuple[float, float]]:
    """(energy drawn in Wh, charge remaining in %) of every report of the pack (BATTERY_STATUS id 0); none
    from a file that is not a readable MCAP log (its run was read otherwise: it tells nothing of the pack)."""
    try:
        return _reports(path, keys.telemetry(vehicle, "BATTERY_STATUS"))
    except (OSError, ValueError, struct.error, McapError):
        return []


def _reports(path: Path, topic: str) -> list[tuple[float, float]]:
    out = []
    for _, _, msg in read_log(path, topics=[topic]):
        if not isinstance(msg, dict) or int(msg.get("id", -1)) != 0:
            continue
        remaining = float(msg.get("battery_remaining", -1))
        energy_hj = float(msg.get("energy_consumed", -1))
        if energy_hj < 0:  # not reported: the charge drawn at the first cell's voltage
            mah, mv = float(msg.get("current_consumed", -1)), float((msg.get("voltages") or [0])[0])
            energy_hj = mah * mv / 1e6 * HJ_PER_WH if mah >= 0 and 0 < mv < 65535 else -1.0
        if remaining >= 0 and energy_hj >= 0:
            out.append((energy_hj / HJ_PER_WH, remaining))
    return out


def read_pack(paths: Iterable[Path], vehicle: str = keys.DEFAULT_VEHICLE) -> PackReading | None:
    """The pack's size fitted to every log's reports (each log's energy counted from its own start), or None
    when the logs carry no pack reports or its charge fell by less than :data:`MIN_SPAN_PERCENT`.

    Each log is its own flight (a cold boot counts from zero), so each gets its own intercept
    and all share one slope: remaining % = start_i - 100 * drawn Wh / capacity.
    """
    drawn, remaining, run = [], [], []
    first_start = None
    for i, path in enumerate(paths):
        reports = _pack_reports(Path(path), vehicle)
        if len(reports) < 2:
            continue
        e, r = np.array(reports, dtype=float).T
        if first_start is None:
            first_start = float(r[0])
        drawn.append(e - e[0])
        remaining.append(r)
        run.append(np.full(e.size, i))
    if not drawn:
        return None
    e, r, k = np.concatenate(drawn), np.concatenate(remaining), np.concatenate(run)
    span = max(float(np.ptp(ri)) for ri in remaining)
    if span < MIN_SPAN_PERCENT:
        return None
    runs = np.unique(k)
    design = np.column_stack([e] + [(k == j).astype(float) for j in runs])
    coef, *_ = np.linalg.lstsq(design, r, rcond=None)
    if coef[0] >= 0:  # the charge did not fall with the energy drawn: nothing to read
        return None
    capacity = -100.0 / float(coef[0])
    start = float(first_start if first_start is not None else r[0])
    usable = (100.0 - PACK_CRITICAL_PERCENT) / 100.0 * capacity
    return PackReading(capacity, start, usable, int(e.size), span)
