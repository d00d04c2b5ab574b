"""A calibration run flown like a plan's scenario: lock-step in the loop, and on the bare front-seat over
loopback MAVLink with the whole vehicle stack; each ends recovered and its log says which legs it flew."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from bridge.mission_upload import MissionItem
from planner.cli import app
from planner.fly.flight import flight_from_plan
from planner.fly.vehicle.run import run_vehicle
from planner.review.logs import read_run
from sim.uuv.geo import LocalFrame
from sim.uuv.metrics import metric_names
from tests.support.bare_vehicle import bare_vehicle

pytestmark = pytest.mark.integration

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
runner = CliRunner()


@pytest.fixture(scope="module")
def plan(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("shakedown")
    result = runner.invoke(app, ["shakedown", str(EXAMPLES / "range2017.toml"), "--out", str(out)])
    assert result.exit_code == 0, result.output
    return out / "plan.json"


def _legs_of(log: Path) -> list[dict]:
    meta = read_run(log).meta
    assert meta["calibration"] == "shakedown" and meta["scenario_id"] == "shakedown"
    return meta["legs"]


def test_in_the_loop_it_ends_recovered_as_predicted_and_the_log_carries_its_legs(plan, tmp_path):
    log = tmp_path / "shakedown.mcap"
    result = runner.invoke(
        app, ["run", str(plan), "--scenario", "shakedown", "--log", str(log)], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    assert "recovered" in result.output
    assert re.search(r"same scores as the batch simulator\s*│\s*yes", result.output), result.output
    legs = _legs_of(log)
    flight = flight_from_plan(plan, "shakedown")
    assert [(leg["name"], leg["kind"]) for leg in legs] == [(leg.name, leg.kind) for leg in flight.legs]
    turns = {leg["name"]: leg["turn_deg"] for leg in legs if leg["kind"] == "turn"}
    assert sorted(turns.values()) == [-180.0, 180.0]
    assert legs[0]["start_s"] == 0.0 and all(a["end_s"] == b["start_s"] for a, b in zip(legs, legs[1:]))
    assert [leg["surface"] for leg in legs if leg["kind"] == "ascent"] == [True]


@pytest.mark.slow
def test_on_a_bare_autopilot_it_ends_recovered_and_the_log_carries_its_legs(plan, tmp_path):
    """Vehicle-paced: real depth (the ascent rises, the dive goes back down), its own clock, the watchdog on."""
    flight = flight_from_plan(plan, "shakedown")
    log = tmp_path / "vehicle.mcap"
    with bare_vehicle(flight.mission, flight.u, speedup=25.0) as (connection, fs):
        result = run_vehicle(flight, connection, log_path=log, timeout_s=120, guard=None)
        uploaded = [MissionItem.from_message(m) for m in fs.mission_items]
    assert result.ended == "recovered" and not result.watchdog, (result.ended, result.watchdog)
    # the vehicle's mission is the run's route: home, where each leg starts (at depth), recovery on top
    frame = LocalFrame(flight.mission.origin_lat, flight.mission.origin_lon)
    assert len(flight.route) == len(flight.legs) + 1 and len(uploaded) == len(flight.route) + 1
    for item, (x, y) in zip(uploaded[1:], flight.route):
        east, north = frame.to_local(item.x * 1e-7, item.y * 1e-7)
        assert math.hypot(east - x, north - y) < 1.0
    assert uploaded[-1].z == 0.0 and all(item.z < 0 for item in uploaded[1:-1])
    names = metric_names(flight.mission)
    assert result.scores[names.index("recovery")] == 1 and result.sim_s <= 15 * 60
    legs = {leg["name"]: leg for leg in _legs_of(log)}
    assert [leg.name for leg in flight.legs] == list(legs)
    t = result.track[:, 0]

    def rows(name: str, skip_s: float):
        return result.track[(t >= legs[name]["start_s"] + skip_s) & (t < legs[name]["end_s"])]

    assert rows("ascent", 10.0)[:, 5].min() == 1  # up on the surface
    assert rows("dive", 10.0)[:, 5].max() == 0  # and back down
    # the track's speed is over ground: legs along the same bearing share the tide, so their difference is the
    # vehicle's own; commanded beyond max_speed, it saturates there
    over, cruise = rows("over_max", 20.0)[:, 6].mean(), rows("cruise", 20.0)[:, 6].mean()
    v = flight.mission.vehicle
    assert abs((over - cruise) - (v.max_speed - v.cruise_speed)) < 0.1, (over, cruise)
