"""The day's noise from a comparison into the re-plan's mission file, and the plan's default dithering from it."""

from __future__ import annotations

import pytest

from planner.plan.generate import GenerateConfig
from planner.review.day_noise import noise_from_comparison, with_execution_noise
from sim.uuv.missionfile import load_mission_text
from tests.sim.uuv.test_simulate import EXAMPLES

TEXT = (EXAMPLES / "range2017.toml").read_text()
COMPARISON = {
    "plan": {"id": "p1", "mission": "range2017"},
    "forecast": {
        "day_noise": {
            "fitted": {"position": 4.25, "time": 12.5, "battery": 0.4},
            "runs": {"position": 6, "time": 5, "battery": 6},
            "prior_weight": 2.0,
        }
    },
}


def test_the_fitted_noise_is_written_once_and_loads():
    noise = noise_from_comparison(COMPARISON)
    assert noise is not None and (noise.position, noise.time, noise.battery) == (4.25, 12.5, 0.4)
    assert "plan p1" in noise.source and "time from 5 run(s)" in noise.source
    text = with_execution_noise(with_execution_noise(TEXT, noise), noise)  # a second calibration replaces it
    assert text.count("[execution_noise]") == 1
    m = load_mission_text(text, "calibrated.toml")
    assert m.execution_noise == noise


def test_the_re_plan_dithers_by_the_days_noise_unless_told_otherwise():
    m = load_mission_text(with_execution_noise(TEXT, noise_from_comparison(COMPARISON)), "calibrated.toml")
    day = GenerateConfig().noise(m)
    assert (day.position_m, day.time_s, day.battery_pct) == (4.25, 12.5, 0.4)
    told = GenerateConfig(dither_sigma="position=20").noise(m)
    assert told.position_m == 20.0 and told.time_s == 30.0
    plain = load_mission_text(TEXT, "range2017.toml")
    assert GenerateConfig().noise(plain).position_m == 10.0


@pytest.mark.parametrize("fitted", [None, {"position": 4.0, "time": 0.0, "battery": 1.0}, {"unit": 0.02}])
def test_a_comparison_without_a_fitted_noise_writes_none(fitted):
    data = {"plan": {}, "forecast": {"day_noise": None if fitted is None else {"fitted": fitted}}}
    assert noise_from_comparison(data) is None


def test_a_bad_noise_table_is_one_line_naming_the_field():
    with pytest.raises(ValueError) as bad:
        load_mission_text(TEXT + "\n[execution_noise]\nposition = 0\ntime = 12\nbattery = 0.4\n", "day.toml")
    assert str(bad.value).startswith("day.toml: execution_noise.position: ") and "\n" not in str(bad.value)
