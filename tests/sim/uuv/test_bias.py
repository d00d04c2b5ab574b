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
