"""The range day's calibration on ArduSub's real firmware: the calibration run flown, the vehicle calibrated from it.

Needs the ArduSub SITL binary named by ``ARDUSUB_SITL`` (CI sets it) and skips with that
reason where it is absent. The run is designed for range2017 (``rapt-plan shakedown``), flown
from a cold boot at speed-up 40 through the vehicle run's bring-up, watchdog and log, and
calibrated from its log alone. What the firmware's BlueROV2 is (a thruster vehicle that
turns in a second, flies an earth-frame velocity, crawls at the surface and draws a
thruster's current) is what the fit must find, whatever the mission file's torpedo says.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from planner.common.plans import load_plan
from planner.fly.ardusub_sitl import ENV, ArduSubSitl, launch_point, sitl_binary
from planner.fly.flight import flight_from_plan
from planner.fly.vehicle.run import run_vehicle
from planner.plan.shakedown import design_shakedown, write_shakedown
from planner.review.calibrate import calibrate
from planner.review.logs import read_run
from planner.review.segment_fit import CONTROL_MARGIN
from sim.uuv.legs import leg_driver, legs_from_json

ROOT = Path(__file__).resolve().parents[3]
MISSION = ROOT / "examples" / "range2017.toml"
#: A BlueROV2's 18 Ah pack (SITL's default is 3.3 Ah).
PACK = {"BATT_CAPACITY": 18000.0, "SIM_BATT_CAP_AH": 18.0}

needs_firmware = pytest.mark.skipif(sitl_binary() is None, reason=f"{ENV} is not set: no ArduSub SITL binary to fly")


@needs_firmware
@pytest.mark.sitl
@pytest.mark.integration
@pytest.mark.slow
def test_one_calibration_run_on_the_firmware_calibrates_the_thruster_vehicle(tmp_path):
    mission = sim.uuv.load_mission(MISSION)
    plan = write_shakedown(design_shakedown(mission), MISSION, tmp_path / "shakedown")
    flight = flight_from_plan(plan, "shakedown")
    log = tmp_path / "shakedown.mcap"
    with ArduSubSitl(launch_point(mission), speedup=40, parameters=PACK) as sitl:
        result = run_vehicle(flight, sitl.connection, log_path=log, timeout_s=120.0)
    assert result.ended == "recovered" and not result.watchdog, (result.ended, result.watchdog)
    assert result.decisions["missed"] == 0

    out = tmp_path / "calibrated.toml"
    cal = calibrate(MISSION, [log], out)  # the calibration run's log alone
    side = json.loads(out.with_suffix(".json").read_text())
    v = cal.vehicle
    # a thruster vehicle, as the firmware's model is: it turns in about a second, at tens of degrees a second,
    # and its draw rises far less than cubically with speed; the pack it carries caps the scenarios' battery
    for n in ("power_exponent", "drag_w", "water.current_scale"):
        assert cal.estimate.identified[n], (n, side.get("unidentified"))
    # the hotel load: from the hold leg, or (one CI flight of this stop) named with the hold that would identify it
    assert cal.estimate.identified["hotel_w"] or "hold" in side["unidentified"]["hotel_w"]
    assert v.power_exponent < 1.5
    assert cal.pack_limits_battery and v.battery_wh < 0.5 * mission.vehicle.battery_wh
    # the firmware feels no tide, whatever the table says, and the file gets that water
    assert cal.value("water.current_scale") < 0.2
    assert sim.uuv.load_mission(out).execution_bias.current_scale < 0.2
    # its speed controller reaches what it is asked up to about 2 m/s and no more: a measured curve, each
    # commanded speed of the legs a knot, where the torpedo's gain x command would run on to 3 m/s
    knots = dict(v.speed_curve)
    assert len(knots) >= 3 and all(cal.estimate.identified[f"speed_curve[{c:g}]"] for c in knots)
    slow, fast = min(knots), max(knots)
    assert knots[slow] == pytest.approx(slow, rel=0.1)
    assert 1.5 < knots[fast] < 2.3 and knots[fast] < 0.8 * fast  # saturated
    # the turn terms: identified as a thruster vehicle's (tens of degrees a second, about a second to close a
    # heading error), or, where a flight's report gaps left the turns out of the replayed segments (1 of 3 flights
    # at speed-up 40 on a loaded machine), kept and named with the leg that would identify them
    turns = ("max_turn_rate_dps", "heading_time_s", "yaw_time_constant_s")
    if all(cal.estimate.identified[n] for n in turns):
        assert v.max_turn_rate_dps > 30 and v.heading_time_s < 2
        assert cal.rms_after["heading_deg"] < 0.2 * cal.rms_before["heading_deg"]
    else:
        assert all("turn" in side["unidentified"][n] for n in turns if not cal.estimate.identified[n])
    # ArduSub's GUIDED flies an earth-frame velocity with an integrator: the fit takes the vector loop, slow part
    # and all, and at the surface the vehicle makes a fraction of what it is asked and draws more
    # (the choice's margin is the test: a thruster vehicle that turns in a second flies a surge loop's track
    # nearly as well, and the two loops' residuals came 0.58 and 0.79 apart on two flights)
    assert v.velocity_control == "vector", cal.control
    rms = cal.control["position_rms_m"]
    assert rms["vector"] < (1 - CONTROL_MARGIN) * rms["surge"]
    assert all(cal.estimate.identified[n] for n in ("surface_max_speed", "surface_power_w")), side["unidentified"]
    assert 0 < v.surface_max_speed < 0.5 * mission.vehicle.cruise_speed and v.surface_power_w > 50
    assert cal.rms_after["position_m"] < cal.rms_before["position_m"]
    assert cal.rms_after["energy_wh"] < cal.rms_before["energy_wh"]

    # the run re-predicted from its legs by the calibrated vehicle (with the battery its gauge counted from) in the
    # water the run measured: its energy within 5 % and its track within a third of the file torpedo's error
    entry = load_plan(plan).scenario("shakedown")
    run = read_run(log)
    calibrated = sim.uuv.load_mission(out)
    in_water = dataclasses.replace(mission, execution_bias=calibrated.execution_bias)
    plant = dataclasses.replace(v, battery_wh=mission.vehicle.battery_wh)
    drive = leg_driver(legs_from_json(entry["legs"]))

    def errors(m, plant=None) -> tuple[float, float]:
        """(path RMS m, energy used predicted / logged - 1) of the run re-predicted."""
        u = np.asarray(entry["u"])[None, :]
        pred = sim.uuv.simulate(m, u, trajectories=True, driver=drive, plant=plant).trajectory(0)
        t = np.clip(run.steps[:, 0], pred[0, 0], pred[-1, 0])
        px, py = np.interp(t, pred[:, 0], pred[:, 1]), np.interp(t, pred[:, 0], pred[:, 2])
        path = float(np.sqrt(np.mean((run.steps[:, 1] - px) ** 2 + (run.steps[:, 2] - py) ** 2)))
        used = run.steps[-1, 4] - run.steps[0, 4]
        energy = (np.interp(t[-1], pred[:, 0], pred[:, 4]) - np.interp(t[0], pred[:, 0], pred[:, 4])) / used - 1
        return path, float(energy)

    path, energy = errors(in_water, plant)
    file_path, file_energy = errors(mission)
    assert abs(energy) < 0.05 and abs(file_energy) > 0.30
    assert path < 10.0 and path < file_path / 3, (path, file_path)
