"""The execution bias a SIL front-seat can be given: parsing ``--inject-bias`` and per-row biases in the batch simulator."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import sim.uuv
from sim.uuv.bias import Bias, parse_bias

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"


@pytest.mark.parametrize(
    "text,expect",
    [
        ("sped=1.1", "sped: unknown bias parameter; choose from speed, current_scale"),
        ("speed", "speed: no value; write speed=<number>"),
        ("speed=fast", "speed: 'fast' is not a number"),
        ("speed=9", "speed: 9 is outside [0.5, 2] x"),
        ("heading=90", "heading: 90 is outside [-45, 45] deg"),
        ("speed=1.1,speed=1.2", "speed: given twice"),
        ("speed=1.1,,battery=1", "empty item"),
        ("current_offset=nan", "current_offset: nan is outside"),
    ],
)
def test_inject_bias_parse_errors_name_the_field_and_the_fix(text, expect):
    with pytest.raises(ValueError) as info:
        parse_bias(text)
    assert expect in str(info.value) and "\n" not in str(info.value)


def test_neutral_bias_is_bit_identical_and_a_bias_is_per_row():
    m = sim.uuv.load_mission(MISSION)
    X = np.random.default_rng(5).random((16, m.dim))
    plain = sim.uuv.simulate(m, X)
    b = Bias(speed=1.1, heading=2.0, battery=0.9, current_scale=1.2, start_time=1800.0)
    mixed = sim.uuv.simulate(m, np.vstack([X, X[:4]]), bias=[Bias()] * 16 + [b] * 4)  # one bias per row
    np.testing.assert_array_equal(mixed.scores[:16], plain.scores)  # neutral: bit for bit
    np.testing.assert_array_equal(sim.uuv.simulate(m, X[:4], bias=b).scores, mixed.scores[16:])
    assert not np.array_equal(mixed.scores[16:], plain.scores[:4], equal_nan=True)


@pytest.mark.parametrize("sets_to_deg", [0.0, 90.0, 200.0, 315.0])
def test_offset_and_cross_make_a_steady_current_from_any_direction(sets_to_deg):
    """A steady 0.3 m/s current setting any way is the flood-direction offset plus the cross term,
    with the table's tide scaled away (ArduSub SITL's current, which knows no tide table)."""
    from sim.uuv.environment import biased_tide

    m = sim.uuv.load_mission(MISSION)
    flood = np.deg2rad(m.current.direction_deg)
    sets = np.deg2rad(sets_to_deg)
    along, across = 0.3 * np.cos(sets - flood), 0.3 * np.sin(sets - flood)
    b = Bias(current_scale=0.0, current_offset=float(along), current_cross=float(across))
    ce, cn = biased_tide(m.current, np.array([0.0, 7200.0, 30000.0]), b)
    np.testing.assert_allclose(ce, 0.3 * np.sin(sets), atol=1e-12)
    np.testing.assert_allclose(cn, 0.3 * np.cos(sets), atol=1e-12)


def test_a_cross_current_moves_the_simulated_vehicle_across_the_flood():
    m = sim.uuv.load_mission(MISSION)
    X = np.random.default_rng(2).random((8, m.dim))
    plain = sim.uuv.simulate(m, X, trajectories=True)
    crossed = sim.uuv.simulate(m, X, trajectories=True, bias=Bias(current_cross=0.3))
    flood = np.deg2rad(m.current.direction_deg)
    right = np.array([np.cos(flood), -np.sin(flood)])  # direction_deg + 90
    flown = [(a, b) for a, b in zip(plain.trajectories, crossed.trajectories) if a is not None]
    assert flown
    for a, b in flown:
        k = min(len(a), len(b), 60)  # the first minutes, before the autonomy's own choices part them
        drift = (b[k - 1, 1:3] - b[0, 1:3]) - (a[k - 1, 1:3] - a[0, 1:3])
        assert drift @ right > 0.5 * np.linalg.norm(drift) > 0
