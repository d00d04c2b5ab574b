"""A run starts at its start, on ArduSub's firmware: a vehicle left armed in GUIDED at depth by a killed run is
surfaced and disarmed first; one away from the start is refused with the distance, or flown there on a
transit leg before the scenario clock starts."""

from __future__ import annotations

import math
import time
from pathlib import Path

import pytest

from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary
from planner.fly.flight import flight_from_plan
from planner.fly.vehicle.bringup import START_TOLERANCE_M
from planner.fly.vehicle.run import run_vehicle
from rapt.errors import InputError
from sim.uuv.missionfile import load_mission
from tests.support.firmware_run import Monitor, kill_mid_scenario

ROOT = Path(__file__).resolve().parents[4]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
MISSION = load_mission(ROOT / "examples" / "range2017.toml")
LAUNCH = launch_point(MISSION)
SPEEDUP = 10.0
GUIDED = 4

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")
pytestmark = [needs_firmware, pytest.mark.sitl, pytest.mark.integration, pytest.mark.slow]


def test_a_killed_runs_vehicle_is_surfaced_disarmed_and_flown_back_to_the_start_before_the_clock():
    flight = flight_from_plan(PLAN, "pair2b")
    sx, sy = MISSION.launch
    with ArduSubSitl(LAUNCH, speedup=SPEEDUP) as sitl:
        monitor = Monitor(sitl.port + 2)
        try:
            # a --no-guard run killed about 150 m along pair2b's first leg
            kill_mid_scenario(sitl.connection, monitor, PLAN, "pair2b", 200.0, "--no-guard")
            time.sleep(1.0)
            assert monitor.modes[-1][1] == GUIDED  # left armed in GUIDED, at depth, with nobody flying it

            # started again without --transit: the earlier run's vehicle is surfaced and disarmed, then refused
            steps: list = []
            with pytest.raises(InputError) as refused:
                run_vehicle(flight, sitl.connection, timeout_s=3.0, say=steps.append)
            line = str(refused.value)
            assert "\n" not in line and line.startswith("--start-tolerance: the vehicle is ") and "--transit" in line
            away = float(line.split("the vehicle is ")[1].split(" m from")[0])
            assert away > 100, line
            [previous] = [s for s in steps if s.name == "previous"]
            assert previous.status == "ok" and "armed in GUIDED from an earlier run" in previous.detail
            assert [s.name for s in steps][:4] == ["heartbeat", "streams", "previous", "estimate"]
            assert "guided" not in [s.name for s in steps]  # refused before anything was commanded for this run

            # with --transit: flown back at depth, logged as a bring-up step; the clock starts at the start
            steps = []
            result = run_vehicle(flight, sitl.connection, timeout_s=3.0, transit=True, say=steps.append)
        finally:
            monitor.close()
    names = [s.name for s in steps]
    assert names.index("depth") < names.index("transit") < names.index("clock"), names
    assert "previous" not in names  # the refused attempt left it disarmed at the surface
    [start] = [s for s in steps if s.name == "start"]
    assert start.status == "note" and "transit leg" in start.detail
    x0, y0 = result.track[0, 1:3]
    assert math.hypot(x0 - sx, y0 - sy) <= START_TOLERANCE_M, result.track[0]
    assert result.track[0, 0] <= MISSION.dt and len(result.track) > 1  # the scenario flew from there (its end is the
    # firmware pack's to call: two flights and a transit on one SITL pack may end it as "watchdog: battery")
