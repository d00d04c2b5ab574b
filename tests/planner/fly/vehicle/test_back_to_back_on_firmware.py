"""Three scenarios flown one after another on one boot of ArduSub's firmware, as a range day does without a
reboot between runs: each brought up, flown, surfaced, logged and compared on its own; each virtual gauge
starts at its own scenario's charge; and the vehicle's estimator origin, set once at the first run, shifts
no later run's positions."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from bridge.logger import read_log
from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary
from planner.fly.flight import flight_from_plan
from planner.fly.vehicle.bringup import START_TOLERANCE_M
from planner.fly.vehicle.run import run_vehicle
from planner.review.compare import compare
from planner.review.runs import CompareConfig
from sim.uuv.missionfile import load_mission
from sim.uuv.scenario import make_scenarios

ROOT = Path(__file__).resolve().parents[4]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
MISSION = load_mission(ROOT / "examples" / "range2017.toml")
LAUNCH = launch_point(MISSION)
#: an 18 Ah pack: three short runs and their transits leave it well above the watchdog's 10 %
PACK = {"BATT_CAPACITY": 18000.0, "SIM_BATT_CAP_AH": 18.0}
SCENARIOS = ("pair1a", "pair2b", "pair3a")

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")
pytestmark = [needs_firmware, pytest.mark.sitl, pytest.mark.integration, pytest.mark.slow]


def test_three_scenarios_back_to_back_on_one_boot_each_start_at_their_start_and_compare(tmp_path):
    sx, sy = MISSION.launch
    results, logs = {}, []
    with ArduSubSitl(LAUNCH, speedup=20.0, parameters=PACK) as sitl:
        for sid in SCENARIOS:
            log = tmp_path / f"{sid}.mcap"
            flight = flight_from_plan(PLAN, sid)
            results[sid] = run_vehicle(flight, sitl.connection, log_path=log, timeout_s=6.0, transit=True)
            logs.append(log)
    for k, (sid, result) in enumerate(results.items()):
        names = [s.name for s in result.timeline]
        assert result.timeline[-1].name == "recover" and "surfaced and disarmed" in result.timeline[-1].detail, sid
        assert "previous" not in names, (sid, names)  # each run left the vehicle disarmed at the surface
        if k > 0:  # flown away by the run before: back to the start before the clock
            assert names.index("transit") < names.index("clock"), (sid, names)
        x0, y0 = result.track[0, 1:3]
        assert math.hypot(x0 - sx, y0 - sy) <= START_TOLERANCE_M, (sid, result.track[0])
    # each run's virtual gauge starts at its own scenario's charge
    flights = {sid: flight_from_plan(PLAN, sid) for sid in SCENARIOS}
    for sid, log in zip(SCENARIOS, logs):
        u = np.asarray(flights[sid].u, dtype=float)[None, :]
        start_pct = 100.0 * float(make_scenarios(MISSION, u).battery0[0])
        gauge = [m for t, _, m in read_log(log) if t == "rapt/uuv1/virtual/BATTERY_STATUS"]
        assert gauge and abs(gauge[0]["battery_remaining"] - start_pct) <= 1.0, (sid, gauge[:1], start_pct)
    # and `compare` reads the three logs as three runs of the plan
    comparison = compare(PLAN, logs, tmp_path / "comparison", CompareConfig(dithers=0, bootstrap=0))
    rows = {row["id"]: row for row in comparison["scenarios"]}
    assert set(rows) == set(SCENARIOS)
    for sid, row in rows.items():
        # the wall-time limit ends a run between two reports: the log may hold the one that came as it ended
        assert row["log_complete"] and abs(row["steps"] - len(results[sid].track)) <= 1, (sid, row)
        assert row["path_error_m"] is not None
