"""The calibration run: it fits each example range, flies its legs as designed in the batch simulator, and is
written as a plan that validates and flies as a scenario with its legs."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import numpy as np
import pytest

import planner
import sim.uuv
from planner.fly.flight import flight_from_plan
from planner.plan.shakedown import ShakedownOptions, design_shakedown, write_shakedown
from sim.uuv.legs import leg_driver
from sim.uuv.simulate import TRAJECTORY_FIELDS

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
VALIDATOR = jsonschema.Draft202012Validator(
    json.loads((Path(planner.__file__).parent / "plan.schema.json").read_text())
)
T, X, Y, SPEED, YAW_RATE, SPEED_CMD, SURFACED = (
    TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "speed", "yaw_rate", "speed_cmd", "surfaced")
)


def _during(track: np.ndarray, leg: dict, skip_s: float = 0.0) -> np.ndarray:
    t = track[:, T]
    return track[(t >= leg["start_s"] + skip_s) & (t < leg["end_s"])]


@pytest.mark.parametrize("name", ["range2017", "uuv18", "imitation7"])
def test_the_run_fits_the_range_and_its_legs_identify_the_vehicle(name):
    mission = sim.uuv.load_mission(EXAMPLES / f"{name}.toml")
    design = design_shakedown(mission)
    v, legs = mission.vehicle, design.leg_entries()
    # flown again in the batch simulator from the legs alone: the same track, ending recovered
    again = sim.uuv.simulate(mission, design.u[None, :], trajectories=True, driver=leg_driver(design.legs))
    track = again.trajectory(0)
    np.testing.assert_array_equal(track, design.track)
    assert again.column("recovery.time_s")[0] == track[-1, T] <= 15 * 60
    assert {"recovery": 1.0, "operational_area": 1.0, "nogo_areas": 1.0, "collisions": 1.0}.items() <= {
        k: again.column(k)[0] for k in ("recovery", "operational_area", "nogo_areas", "collisions")
    }.items()
    # inside the area and clear of every no-go area, barrier and obstacle by the margin
    assert min(design.clearance.values()) >= ShakedownOptions().margin_m
    # at least three speeds, one above max_speed, each reached steadily (saturating at max_speed)
    straight = [leg for leg in legs if leg["kind"] == "straight"]
    speeds = sorted({leg["speed"] for leg in straight})
    assert len(speeds) >= 3 and speeds[-1] > v.max_speed and speeds[0] < v.cruise_speed
    for leg in straight:
        steady = _during(track, leg, skip_s=5 * v.surge_time_constant_s)
        assert len(steady) >= 20
        np.testing.assert_allclose(steady[:, SPEED], min(leg["speed"], v.max_speed), atol=0.02)
    # turns both ways, each at the turn-rate limit for a while
    turns = {np.sign(leg["turn_deg"]): _during(track, leg) for leg in legs if leg["kind"] == "turn"}
    assert set(turns) == {1.0, -1.0}
    for sign, rows in turns.items():
        rate = np.rad2deg(rows[:, YAW_RATE]) * sign
        assert rate.max() > 0.95 * v.max_turn_rate_dps and (rate > 0.9 * v.max_turn_rate_dps).sum() >= 4
    # a hold at speed 0, an ascent to the surface and a dive back
    kinds = {leg["kind"]: leg for leg in legs}
    assert {"hold", "ascent", "dive", "return"} <= set(kinds) and legs[-1]["kind"] == "return"
    assert np.all(_during(track, kinds["hold"])[:, SPEED_CMD] == 0)
    assert np.all(_during(track, kinds["ascent"], skip_s=mission.dt)[:, SURFACED] == 1)
    assert np.all(_during(track, kinds["dive"], skip_s=mission.dt)[:, SURFACED] == 0)
    rx, ry = mission.recovery
    assert track[-1, SURFACED] == 1 and np.hypot(track[-1, X] - rx, track[-1, Y] - ry) <= mission.recovery_radius


def test_the_plan_validates_and_flies_as_a_scenario_with_its_legs(tmp_path):
    out = tmp_path / "shakedown"
    path = EXAMPLES / "range2017.toml"
    write_shakedown(design_shakedown(sim.uuv.load_mission(path)), path, out)
    plan = json.loads((out / "plan.json").read_text())
    VALIDATOR.validate(plan)
    scenario = plan["scenarios"][0]
    assert scenario["id"] == "shakedown" and plan["run_order"] == ["shakedown"]
    # the centre of the unit cube, at the range's resolution: what is simulated is what the range sets up
    assert plan["calibration"]["row"] == "centre of the unit cube" and np.allclose(scenario["u"], 0.5, atol=2e-3)
    mission = sim.uuv.load_mission(path)
    assert scenario["parameters"] == json.loads(json.dumps(mission.space.decode(np.array([scenario["u"]]))[0]))
    assert scenario["parameters"]["start_battery"] == 0.225 and scenario["parameters"]["tx_x"] == -300.0
    assert sorted(p.name for p in out.iterdir()) == [
        "plan.json",
        "shakedown.geojson",
        "shakedown.plan",
        "shakedown.waypoints",
    ]
    # the waypoint file lists the legs' turn points, the hold as a timed loiter, ending at the recovery point
    lines = (out / "shakedown.waypoints").read_text().splitlines()
    assert len(lines) == 2 + len(scenario["legs"]) + 1 and lines[-1].split("\t")[3] == "16"
    assert sum(line.split("\t")[3] == "19" for line in lines[2:]) == 1
    flight = flight_from_plan(out / "plan.json", "shakedown")
    assert [leg.name for leg in flight.legs] == [leg["name"] for leg in scenario["legs"]]
    # a pair scenario still needs its dithering; a calibration plan has no pairs
    bad = json.loads(json.dumps(plan))
    bad["pairs"] = [{"id": 1}]
    del bad["scenarios"][0]["legs"]
    paths = {tuple(e.absolute_path) for e in VALIDATOR.iter_errors(bad)}
    assert ("pairs",) in paths and ("scenarios", 0) in paths
