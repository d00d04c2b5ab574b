"""The day's bias from a morning's comparison into the afternoon's mission file, and fits relative to it."""

from __future__ import annotations

import json

import numpy as np
import pytest

import sim.uuv
from planner.review.biasfit import fit_bias
from planner.review.calibrate import calibrate
from planner.review.daybias import WATER_FIELDS, day_bias_record, water_from_comparison, with_execution_bias
from sim.uuv.bias import Bias, compose
from sim.uuv.missionfile import load_mission_text
from tests.planner.review.test_biasfit import scenarios, start_times
from tests.sim.uuv.test_simulate import EXAMPLES
from tests.support.simlogs import sim_runs

TEXT = (EXAMPLES / "range2017.toml").read_text()
MISSION = sim.uuv.load_mission(EXAMPLES / "range2017.toml")


def comparison(tmp_path, *, used=True, assumed=None, mission="range2017", identified=WATER_FIELDS + ("speed",)):
    """A comparison.json as rapt-plan compare writes it (the records calibrate reads)."""
    fitted = {
        "speed": 1.2,
        "current_scale": 0.5,
        "current_offset": 0.1,
        "heading": 2.0,
        "battery": 1.1,
        "start_time": 600.0,
    }
    data = {
        "schema": "rapt.comparison/2",
        "plan": {"id": "p1", "mission": mission},
        "bias": {n: {"estimate": v, "stderr": 0.01, "identified": n in identified} for n, v in fitted.items()},
        "correction": {"used": used},
    }
    if assumed is not None:
        data["day_bias"] = day_bias_record(
            load_mission_text(TEXT + with_table(assumed), "day"), Bias(**fitted), Bias(**fitted)
        )
    path = tmp_path / "comparison.json"
    path.write_text(json.dumps(data))
    return path


def with_table(b: Bias) -> str:
    return "\n[execution_bias]\n" + "\n".join(f"{k} = {v!r}" for k, v in b.to_dict().items()) + "\n"


def test_only_identified_cross_validated_water_is_taken_speed_and_battery_are_dropped(tmp_path):
    water = water_from_comparison(comparison(tmp_path, identified=("current_scale", "start_time", "speed")), MISSION)
    assert water.bias == Bias(current_scale=0.5, start_time=600.0)
    assert set(water.fields) == {"current_scale", "start_time"}
    assert "not identified" in water.dropped["current_offset"] and "not identified" in water.dropped["heading"]
    assert "calibrated vehicle" in water.dropped["speed"] and "calibrated vehicle" in water.dropped["battery"]
    assert "plan p1" in water.source and "comparison.json sha256" in water.source


def test_a_correction_that_did_not_cross_validate_writes_neutral_water(tmp_path):
    water = water_from_comparison(comparison(tmp_path, used=False), MISSION)
    assert water.bias.is_neutral and not water.fields
    assert all("did not cross-validate" in water.dropped[n] for n in WATER_FIELDS)


def test_a_comparison_of_a_plan_with_a_day_bias_gives_the_total(tmp_path):
    assumed = Bias(current_scale=0.4, current_offset=-0.2, start_time=100.0, heading=1.0)
    water = water_from_comparison(comparison(tmp_path, assumed=assumed, identified=("current_scale",)), MISSION)
    # fitted current_scale 0.5 relative to 0.4: 0.2 in all; the others as the plan assumed
    assert water.bias.current_scale == pytest.approx(0.2)
    assert (water.bias.current_offset, water.bias.start_time, water.bias.heading) == (-0.2, 100.0, 1.0)


@pytest.mark.parametrize(
    "content,expect",
    [
        ("not json", "is not JSON"),
        ('{"schema": "rapt.plan/1"}', "is not a comparison"),
        ('{"schema": "rapt.comparison/2", "plan": {}}', "has no 'bias' record"),
    ],
)
def test_a_bad_comparison_is_one_line(tmp_path, content, expect):
    path = tmp_path / "c.json"
    path.write_text(content)
    with pytest.raises(ValueError) as info:
        water_from_comparison(path, MISSION)
    assert str(info.value).startswith("--bias: ") and expect in str(info.value) and "\n" not in str(info.value)


def test_a_comparison_of_another_mission_is_refused(tmp_path):
    with pytest.raises(ValueError, match=r"--bias: .* mission 'other', but the mission file is 'range2017'"):
        water_from_comparison(comparison(tmp_path, mission="other"), MISSION)


def test_the_written_table_loads_and_replaces_an_earlier_one(tmp_path):
    water = water_from_comparison(comparison(tmp_path), MISSION)
    text = with_execution_bias(TEXT + with_table(Bias(current_scale=2.0)) + "\n# trailing\n", water)
    assert text.count("[execution_bias]") == 1
    m = load_mission_text(text, "calibrated.toml")
    assert m.execution_bias == water.bias and m.execution_bias_source == water.source
    assert m.vehicle == MISSION.vehicle and m.space.names == MISSION.space.names


def test_a_fit_on_logs_of_the_planned_water_is_neutral_and_otherwise_relative():
    day_bias = Bias(current_scale=0.4, speed=1.1)
    day = load_mission_text(TEXT + with_table(day_bias), "day.toml")
    U = scenarios(MISSION, 3)
    t0 = start_times(MISSION, U)
    # the vehicle flew the water the plan was made for: nothing left to fit
    same = fit_bias(day, sim_runs(MISSION, U, bias=day_bias), t0, bootstrap=0)
    assert same.bias.speed == pytest.approx(1.0, abs=1e-3) and same.rms_position_m < 0.05
    # it flew other water: the fit is what remains on top of the day's bias
    truth = Bias(current_scale=0.4, speed=1.2)
    rest = fit_bias(day, sim_runs(MISSION, U, bias=truth), t0, bootstrap=0, fit=("speed",))
    assert rest.bias.speed == pytest.approx(1.2 / 1.1, abs=2e-3)
    assert compose(day_bias, rest.bias).speed == pytest.approx(1.2, abs=2e-3)
    np.testing.assert_allclose(rest.rms_position_m, 0.0, atol=0.05)


def test_calibrate_refuses_an_out_whose_sidecar_would_overwrite_the_comparison(tmp_path):
    cmp = comparison(tmp_path)
    before = cmp.read_bytes()
    logs = [tmp_path / "a.mcap", tmp_path / "b.mcap"]
    with pytest.raises(ValueError, match=r"^--out: .* would overwrite the --bias input"):
        calibrate(EXAMPLES / "range2017.toml", logs, tmp_path / "comparison.toml", bias=cmp)
    assert cmp.read_bytes() == before and not (tmp_path / "comparison.toml").exists()
