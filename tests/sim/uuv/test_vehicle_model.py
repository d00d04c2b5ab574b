"""The vehicle model's power exponent and ascent rate: defaults change nothing, other values do what they say."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from rapt.errors import InputError
from sim.uuv.interface import DEPTH_M
from sim.uuv.scenario import make_scenarios
from sim.uuv.simulate import TRAJECTORY_FIELDS
from sim.uuv.vehicle import propulsion_power, reached_speed
from sim.uuv.world import World

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"


@pytest.fixture(scope="module")
def mission():
    return sim.uuv.load_mission(MISSION)


def _with_vehicle_lines(tmp_path: Path, *lines: str) -> Path:
    """range2017.toml with ``lines`` added at the top of its [vehicle] table."""
    text = MISSION.read_text(encoding="utf-8")
    assert "\n[vehicle]\n" in text
    out = tmp_path / "m.toml"
    out.write_text(text.replace("\n[vehicle]\n", "\n[vehicle]\n" + "".join(f"{ln}\n" for ln in lines), 1))
    return out


@pytest.mark.parametrize("stochastic", [False, True])
def test_explicit_default_exponent_and_ascent_rate_score_bit_for_bit_as_today(mission, tmp_path, stochastic):
    explicit = sim.uuv.load_mission(_with_vehicle_lines(tmp_path, "power_exponent = 3.0", "ascent_rate_mps = 0.0"))
    assert explicit.vehicle.power_exponent == 3.0 and explicit.vehicle.ascent_rate_mps == 0.0
    X = np.random.default_rng(5).random((8, mission.dim))
    a = sim.uuv.simulate(mission, X, seed=3, stochastic=stochastic, trajectories=True)
    b = sim.uuv.simulate(explicit, X, seed=3, stochastic=stochastic, trajectories=True)
    np.testing.assert_array_equal(a.scores, b.scores)
    np.testing.assert_array_equal(a.modes, b.modes)
    for ta, tb in zip(a.trajectories, b.trajectories):
        if ta is not None:
            np.testing.assert_array_equal(ta, tb)


def test_power_follows_the_exponent(mission):
    v = dataclasses.replace(mission.vehicle, hotel_w=50.0, drag_w=100.0, cruise_speed=1.0, power_exponent=1.0)
    np.testing.assert_allclose(propulsion_power(v, np.array([0.0, 0.5, 1.0, 2.0])), [50.0, 100.0, 150.0, 250.0])
    cubic = dataclasses.replace(v, power_exponent=3.0)
    np.testing.assert_allclose(propulsion_power(cubic, np.array([0.5, 2.0])), [62.5, 850.0])


@pytest.mark.parametrize("rate", [0.3, 0.05])
def test_a_vehicle_surfaces_only_after_rising_from_its_depth_at_its_ascent_rate(mission, rate):
    scen = make_scenarios(mission, np.full((1, mission.dim), 0.5))
    world = World(scen, plant=dataclasses.replace(mission.vehicle, ascent_rate_mps=rate))
    one, up, down = np.ones(1, bool), np.ones(1, bool), np.zeros(1, bool)
    steps = 0
    while not world.surfaced[0]:
        world.advance(steps * mission.dt, np.zeros(1), np.zeros(1), up, one)
        steps += 1
        assert steps < 1000
    assert steps == math.ceil(DEPTH_M / (rate * mission.dt) - 1e-9)
    # told to dive, it leaves the surface at once and is back at its running depth at the same rate
    world.advance(steps * mission.dt, np.zeros(1), np.zeros(1), down, one)
    assert not world.surfaced[0] and world.depth[0] == pytest.approx(min(rate * mission.dt, DEPTH_M))


def test_a_slow_ascent_delays_every_surfacing_of_a_batch_run(mission):
    X = np.random.default_rng(2).random((12, mission.dim))
    fast = sim.uuv.simulate(mission, X, trajectories=True)
    slow = sim.uuv.simulate(
        mission, X, trajectories=True, plant=dataclasses.replace(mission.vehicle, ascent_rate_mps=0.1)
    )
    col = TRAJECTORY_FIELDS.index("surfaced")
    surfacings = 0
    for tf, ts in zip(fast.trajectories, slow.trajectories):
        if tf is None:
            continue
        first_fast = np.flatnonzero(tf[:, col] > 0)
        if first_fast.size == 0:
            continue
        surfacings += 1
        first_slow = np.flatnonzero(ts[:, col] > 0)
        # 2 m at 0.1 m/s: 20 s, ten 2-s steps later than the instantaneous vehicle (or never, if the run ends first)
        assert first_slow.size == 0 or first_slow[0] >= first_fast[0] + 9
    assert surfacings >= 3


@pytest.mark.parametrize(
    ("line", "field"),
    [
        ("ascent_rate_mps = -0.2", "vehicle.ascent_rate_mps"),
        ("power_exponent = 7.0", "vehicle.power_exponent"),
        ("power_exponent = 0.1", "vehicle.power_exponent"),
        ("surface_max_speed = -0.3", "vehicle.surface_max_speed"),
        ("surface_power_w = -500.0", "vehicle.surface_power_w"),
    ],
)
def test_bad_exponent_or_ascent_rate_is_a_one_line_error_naming_the_field(tmp_path, line, field):
    with pytest.raises(InputError) as e:
        sim.uuv.load_mission(_with_vehicle_lines(tmp_path, line))
    msg = str(e.value)
    assert field in msg and "\n" not in msg


# -- a measured speed curve -----------------------------------------------------------------------
CURVE = "speed_curve = [[1.0, 0.87], [2.0, 1.95], [3.0, 2.05]]"


def test_a_speed_curve_sets_the_speed_each_command_settles_at(mission, tmp_path):
    """Knots interpolate from (0, 0) and hold beyond the last (a controller that saturates gradually): no
    speed_gain x command capped at max_speed says that. A curve never falls (the mission file refuses one)."""
    curved = sim.uuv.load_mission(_with_vehicle_lines(tmp_path, CURVE)).vehicle
    assert curved.speed_curve == ((1.0, 0.87), (2.0, 1.95), (3.0, 2.05))
    got = reached_speed(curved, np.array([-1.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 5.0]))
    assert got == pytest.approx([0.0, 0.435, 0.87, 1.41, 1.95, 2.0, 2.05, 2.05])
    # without a curve: speed_gain x the command, at most max_speed
    plain = dataclasses.replace(mission.vehicle, speed_gain=0.8, max_speed=1.5)
    assert reached_speed(plain, np.array([1.0, 3.0])) == pytest.approx([0.8, 1.5])


def test_a_vehicle_with_a_curve_settles_where_the_curve_says(mission, tmp_path):
    curved = sim.uuv.load_mission(_with_vehicle_lines(tmp_path, CURVE))
    scen = make_scenarios(curved, np.full((3, curved.dim), 0.5))
    world = World(scen)
    speeds = np.array([1.0, 2.0, 3.0])
    for k in range(60):  # 120 s: 30 surge time constants
        world.advance(k * curved.dt, world.state.heading.copy(), speeds, np.zeros(3, dtype=bool), np.ones(3, bool))
    assert world.state.surge == pytest.approx([0.87, 1.95, 2.05], rel=1e-6)


@pytest.mark.parametrize(
    "value",
    ["[[1.0, 0.87], [0.5, 1.0]]", "[[0.0, 0.5]]", "[[1.0, -0.1]]", "[[1.0]]", "[1.0, 2.0]", '"fast"', "[]"],
)
def test_a_bad_speed_curve_is_a_one_line_error_naming_the_knot(tmp_path, value):
    with pytest.raises(InputError) as e:
        sim.uuv.load_mission(_with_vehicle_lines(tmp_path, f"speed_curve = {value}"))
    msg = str(e.value)
    assert "vehicle.speed_curve" in msg and "\n" not in msg and "[[commanded, reached]" in msg


# -- the vehicle at the surface ---------------------------------------------------------------------
def test_at_the_surface_a_vehicle_makes_at_most_its_surface_speed_and_draws_more(mission, tmp_path):
    """Two vehicles told the same: the surfaced one settles at surface_max_speed and draws surface_power_w
    more than its speed's propulsion power; the submerged one is untouched by either."""
    m = sim.uuv.load_mission(_with_vehicle_lines(tmp_path, "surface_max_speed = 0.4", "surface_power_w = 150.0"))
    scen = make_scenarios(m, np.full((2, m.dim), 0.5))
    world = World(scen)
    e0 = world.state.energy_wh.copy()
    surface = np.array([True, False])
    for k in range(60):
        world.advance(k * m.dt, world.state.heading.copy(), np.full(2, 2.0), surface, np.ones(2, bool))
    assert world.surfaced.tolist() == [True, False]
    assert world.state.surge == pytest.approx([0.4, 2.0], rel=1e-6)
    # over the last step both are settled: the draw is the speed's power, plus 150 W at the surface
    before = world.state.energy_wh.copy()
    world.advance(60 * m.dt, world.state.heading.copy(), np.full(2, 2.0), surface, np.ones(2, bool))
    watts = (before - world.state.energy_wh) * 3600.0 / m.dt
    expected = propulsion_power(m.vehicle, np.array([0.4, 2.0])) + np.array([150.0, 0.0])
    assert watts == pytest.approx(expected, rel=1e-6)
    assert np.all(e0 > world.state.energy_wh)
