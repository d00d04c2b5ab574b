"""The mission file's ``[execution_bias]`` table: the day's water and vehicle, flown by every simulation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from sim.uuv.bias import Bias, compose
from sim.uuv.missionfile import load_mission_text
from sim.uuv.scenario import make_scenarios
from sim.uuv.world import World

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"
DAY = Bias(current_scale=0.34, current_offset=0.1, heading=3.0, start_time=600.0, speed=1.1, battery=0.9)


def with_table(body: str) -> str:
    return MISSION.read_text() + "\n[execution_bias]\n" + body + "\n"


def table_of(b: Bias, source: str = "morning compare") -> str:
    return with_table("\n".join(f"{k} = {v!r}" for k, v in b.to_dict().items()) + f'\nsource = "{source}"')


@pytest.fixture(scope="module")
def rows():
    m = sim.uuv.load_mission(MISSION)
    return np.random.default_rng(7).random((12, m.dim))


def test_the_table_loads_into_the_mission_with_its_source():
    m = load_mission_text(table_of(DAY), "day.toml")
    assert m.execution_bias == DAY and m.execution_bias_source == "morning compare"
    plain = sim.uuv.load_mission(MISSION)
    assert plain.execution_bias.is_neutral and plain.execution_bias_source is None
    partial = load_mission_text(with_table("current_scale = 0.5"), "p.toml")
    assert partial.execution_bias == Bias(current_scale=0.5)  # omitted keys stay neutral


@pytest.mark.parametrize(
    "body,expect",
    [
        ("current_scal = 0.3", "execution_bias.current_scal: unknown key (did you mean 'current_scale'?)"),
        ("current_scale = 5.0", "execution_bias.current_scale: 5 is above the maximum 3; use a value in [0, 3]"),
        ("heading = -90", "execution_bias.heading: -90 is below the minimum -45"),
        ('start_time = "1h"', "execution_bias.start_time: expected a number, got str"),
        ("source = 3", "execution_bias.source: expected a non-empty string"),
    ],
)
def test_a_bad_table_is_one_line_naming_the_field_and_the_fix(body, expect):
    with pytest.raises(ValueError) as info:
        load_mission_text(with_table(body), "bad.toml")
    msg = str(info.value)
    assert msg.startswith("bad.toml: ") and expect in msg and "\n" not in msg


def test_a_table_that_is_not_a_table_is_refused():
    with pytest.raises(ValueError, match=r"execution_bias: expected a table"):
        load_mission_text(MISSION.read_text().replace("[mission]", "execution_bias = 1\n[mission]", 1), "x.toml")


def test_a_neutral_table_is_bit_identical_to_no_table(rows):
    plain = sim.uuv.simulate(sim.uuv.load_mission(MISSION), rows, trajectories=True)
    neutral = sim.uuv.simulate(
        load_mission_text(with_table("current_scale = 1.0\nheading = 0.0"), "n"), rows, trajectories=True
    )
    np.testing.assert_array_equal(neutral.scores, plain.scores)
    for a, b in zip(neutral.trajectories, plain.trajectories):
        np.testing.assert_array_equal(a, b)


def test_a_table_flies_exactly_as_the_same_bias_argument_and_composes_with_one(rows):
    m = sim.uuv.load_mission(MISSION)
    day = load_mission_text(table_of(DAY), "day.toml")
    by_table = sim.uuv.simulate(day, rows, trajectories=True)
    by_arg = sim.uuv.simulate(m, rows, trajectories=True, bias=DAY)
    np.testing.assert_array_equal(by_table.scores, by_arg.scores)
    for a, b in zip(by_table.trajectories, by_arg.trajectories):
        np.testing.assert_array_equal(a, b)
    assert not np.array_equal(by_table.scores, sim.uuv.simulate(m, rows).scores, equal_nan=True)
    # a bias given on top is relative to the table: scales multiply, offsets add
    extra = Bias(current_scale=2.0, current_offset=-0.05, start_time=300.0, speed=0.9)
    on_top = sim.uuv.simulate(day, rows, bias=extra)
    np.testing.assert_array_equal(on_top.scores, sim.uuv.simulate(m, rows, bias=compose(DAY, extra)).scores)


def test_compose_multiplies_scales_and_adds_offsets():
    a = Bias(
        speed=1.2, current_scale=0.5, current_offset=0.2, current_cross=0.1, heading=2.0, battery=0.8, start_time=100.0
    )
    b = Bias(
        speed=1.5,
        current_scale=0.5,
        current_offset=-0.5,
        current_cross=0.3,
        heading=-3.0,
        battery=2.0,
        start_time=-400.0,
    )
    c = compose(a, b)
    assert c.to_dict() == pytest.approx(
        {
            "speed": 1.8,
            "current_scale": 0.25,
            "current_offset": -0.3,
            "current_cross": 0.4,
            "heading": -1.0,
            "battery": 1.6,
            "start_time": -300.0,
        }
    )
    assert compose(a, Bias()) is a and compose(Bias(), b) is b
    assert compose(Bias(speed=1.5), Bias(speed=1.5)).speed == 2.25  # may leave the input limits


def test_the_front_seat_world_flies_the_day_water():
    day = load_mission_text(table_of(DAY), "day.toml")
    u = np.full((1, day.dim), 0.5)
    w = World(make_scenarios(day, u))
    assert w.bias.current_scale[0] == 0.34 and w.bias.start_time[0] == 600.0
    assert w.bias.heading_rad[0] == np.deg2rad(3.0)
