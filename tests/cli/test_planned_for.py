"""A plan records the vehicle and the water it was made for, and is made for them."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import sim.uuv
from planner.cli import app
from planner.plan.planned_for import planned_for, summary_lines
from sim.uuv.bias import Bias
from sim.uuv.scoring import MODE_NAMES
from tests.planner.plan.test_generate import PLAN_VALIDATOR
from tests.sim.uuv.test_simulate import EXAMPLES

TEXT = (EXAMPLES / "range2017.toml").read_text()
DAY = Bias(current_scale=0.34, start_time=900.0)
TABLE = '\n[execution_bias]\ncurrent_scale = 0.34\nstart_time = 900.0\nsource = "compare of the morning"\n'
CALIBRATED = (
    "# Calibrated by rapt-plan calibrate from 2 run log(s):\n#   a.mcap  (scenario pair1a, sha256 0123456789ab)\n"
    "# Everything below is the input mission file; only those [vehicle] values changed.\n\n"
)


@pytest.fixture(scope="module")
def day_plan(tmp_path_factory):
    base = tmp_path_factory.mktemp("day")
    day_file = base / "calibrated.toml"
    day_file.write_text(CALIBRATED + TEXT + TABLE)
    out = base / "plan"
    result = CliRunner().invoke(
        app,
        ["generate", str(day_file), "--out", str(out), "--budget", "500", "--pairs", "2", "--dithers", "0"],
        env={"COLUMNS": "200"},
    )
    assert result.exit_code == 0, result.output
    return json.loads((out / "plan.json").read_text()), result.output, out


def test_the_plan_records_its_vehicle_and_water_and_is_schema_valid(day_plan):
    plan, _, _ = day_plan
    PLAN_VALIDATOR.validate(plan)
    rec = plan["mission"]["planned_for"]
    assert rec["mission_sha256"] == plan["mission"]["sha256"]
    assert rec["water"]["execution_bias"] == DAY.to_dict() and rec["water"]["source"] == "compare of the morning"
    assert rec["vehicle"]["calibrated"] and "a.mcap" in rec["vehicle"]["calibration"][1]


def test_the_terminal_summary_and_the_report_say_what_water_was_planned_for(day_plan):
    _, output, out = day_plan
    assert "planned for: calibrated vehicle" in output
    assert "water: day's bias current_scale 0.34, start_time 900 s — from compare of the morning" in output
    report = (out / "report.html").read_text()
    assert "calibrated vehicle" in report and "current_scale 0.34, start_time 900 s" in report


def test_the_plan_predictions_fly_the_day_water(day_plan):
    plan, _, _ = day_plan
    day = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    U = np.array([s["u"] for s in plan["scenarios"]])
    modes = [s["predicted"]["mode"] for s in plan["scenarios"]]
    in_day = sim.uuv.simulate(day, U, bias=DAY)
    assert modes == [MODE_NAMES[m] for m in in_day.modes]


def test_a_mission_file_without_a_table_or_calibration_records_nothing():
    m = sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    assert planned_for(m, TEXT, "0" * 64) is None and summary_lines(None) == []
