"""The vehicle's own pack read from its logs: its size, and the energy left to the watchdog's limit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.fly.sil.loop import run_sil
from planner.review.pack import PACK_CRITICAL_PERCENT, read_pack

MISSION = sim.uuv.load_mission(Path(__file__).resolve().parents[3] / "examples" / "range2017.toml")


@pytest.fixture(scope="module")
def sil_log(tmp_path_factory) -> Path:
    """One lock-step SIL flight of range2017's centre scenario, logged (its pack is the mission's battery)."""
    log = tmp_path_factory.mktemp("pack") / "centre.mcap"
    run_sil(MISSION, np.full(MISSION.dim, 0.5), log_path=log)
    return log


def test_the_pack_size_is_read_from_what_it_reports(sil_log):
    got = read_pack([sil_log])
    assert got is not None and got.reports > 100
    assert got.capacity_wh == pytest.approx(MISSION.vehicle.battery_wh, rel=0.02)
    left = (100.0 - PACK_CRITICAL_PERCENT) / 100.0 * got.capacity_wh
    assert got.usable_wh == pytest.approx(left) and got.usable_wh < got.capacity_wh


def test_two_flights_share_one_pack_size(sil_log, tmp_path):
    twice = read_pack([sil_log, sil_log])
    once = read_pack([sil_log])
    assert twice is not None and once is not None
    assert twice.capacity_wh == pytest.approx(once.capacity_wh, rel=1e-9) and twice.reports == 2 * once.reports


def test_no_logs_tell_nothing():
    assert read_pack([]) is None


def test_calibration_caps_the_battery_at_a_smaller_pack_and_keeps_it_at_the_files_own(sil_log):
    """A vehicle whose pack is the file's battery keeps it; one whose pack is far smaller gets the pack's energy."""
    import dataclasses
    from types import SimpleNamespace

    from planner.review.calibrate import _limit_battery_to_pack

    same = SimpleNamespace(vehicle=MISSION.vehicle, pack=None, pack_limits_battery=False)
    _limit_battery_to_pack(same, [sil_log])  # type: ignore[arg-type]
    assert not same.pack_limits_battery and same.vehicle.battery_wh == MISSION.vehicle.battery_wh
    bigger = dataclasses.replace(MISSION.vehicle, battery_wh=3 * MISSION.vehicle.battery_wh)
    small = SimpleNamespace(vehicle=bigger, pack=None, pack_limits_battery=False)
    _limit_battery_to_pack(small, [sil_log])  # type: ignore[arg-type]
    assert small.pack_limits_battery
    assert small.vehicle.battery_wh == pytest.approx(0.9 * MISSION.vehicle.battery_wh, rel=0.02)
