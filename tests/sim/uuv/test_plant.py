"""The vehicle block's speed gain and the plant override of the batch simulator."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from rapt.errors import InputError
from sim.uuv.autonomy import Autonomy
from sim.uuv.scenario import make_scenarios
from sim.uuv.simulate import TRAJECTORY_FIELDS, run_scenarios
from sim.uuv.world import World

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"


@pytest.fixture(scope="module")
def mission():
    return sim.uuv.load_mission(MISSION)


@pytest.fixture(scope="module")
def X(mission):
    return np.random.default_rng(11).random((6, mission.dim))


def test_a_plant_equal_to_the_mission_vehicle_and_a_unit_speed_gain_change_nothing(mission, X):
    plain = sim.uuv.simulate(mission, X, trajectories=True)
    same = sim.uuv.simulate(mission, X, trajectories=True, plant=dataclasses.replace(mission.vehicle))
    gain1 = sim.uuv.simulate(mission, X, trajectories=True, plant=dataclasses.replace(mission.vehicle, speed_gain=1.0))
    for r in (same, gain1):
        np.testing.assert_array_equal(r.scores, plain.scores)
        for a, b in zip(r.trajectories, plain.trajectories):
            np.testing.assert_array_equal(a, b)


def test_a_plant_flies_the_vehicles_while_the_autonomy_keeps_the_mission_vehicle(mission, X):
    """simulate(plant=other): the world flies ``other``, the autonomy still plans with the mission's vehicle."""
    other = dataclasses.replace(mission.vehicle, speed_gain=0.8, max_turn_rate_dps=8.0, hotel_w=60.0, drag_w=220.0)
    got = sim.uuv.simulate(mission, X, trajectories=True, plant=other)
    scen = make_scenarios(mission, X)
    rows = np.flatnonzero(scen.valid)
    world = World(scen.select(rows), plant=other)
    assert world.spec is other and Autonomy(scen.select(rows)).spec is mission.vehicle
    scores, trajs = run_scenarios(scen.select(rows), None, True, plant=other)
    np.testing.assert_array_equal(got.scores[rows], scores)
    plain = sim.uuv.simulate(mission, X, trajectories=True)
    speed = TRAJECTORY_FIELDS.index("speed")
    for r, t in zip(rows.tolist(), trajs):
        np.testing.assert_array_equal(got.trajectory(r), t)
        # the plant reaches 0.8 of the command (at most 0.8 x 3 m/s) where the mission's vehicle reaches it
        assert got.trajectory(r)[:, speed].max() <= 0.8 * mission.vehicle.max_speed + 1e-9
        assert not np.array_equal(got.trajectory(r), plain.trajectory(r))


def test_speed_gain_scales_the_speed_reached_and_is_validated(mission, tmp_path):
    text = MISSION.read_text()
    assert "[vehicle]\n" in text
    p = tmp_path / "slow.toml"
    p.write_text(text.replace("[vehicle]\n", "[vehicle]\nspeed_gain = 0.8\n"))
    slow = sim.uuv.load_mission(p)
    assert slow.vehicle.speed_gain == 0.8
    p.write_text(text.replace("[vehicle]\n", "[vehicle]\nspeed_gain = 0\n"))
    with pytest.raises(InputError, match=r"vehicle.speed_gain: 0 must be > 0"):
        sim.uuv.load_mission(p)
