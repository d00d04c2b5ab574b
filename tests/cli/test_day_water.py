"""The day's loop on lock-step SIL: a plan made for the day's water, flown in it, compared, calibrated again.

The mission file carries the morning's ``[execution_bias]`` (a tide a third of the table's,
running half an hour late).  Its plan is flown in SIL — the front-seat flies the plan's
mission, so the day's water — and ``rapt-plan compare`` then finds nothing left to
correct: the fitted bias is relative to the water the plan assumed.  ``rapt-plan
calibrate --bias`` on that comparison writes the water back, as the plan assumed it.
"""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

import sim.uuv
from planner.cli import app
from sim.uuv.bias import Bias
from tests.support.sil_day import MISSION, digests, fly_plan

pytestmark = [pytest.mark.slow, pytest.mark.integration]
runner = CliRunner()
DAY = Bias(current_scale=0.34, start_time=1800.0)
TABLE = '\n[execution_bias]\ncurrent_scale = 0.34\nstart_time = 1800.0\nsource = "morning compare"\n'


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    base = tmp_path_factory.mktemp("day_water")
    day_file = base / "day.toml"
    day_file.write_text(MISSION.read_text() + TABLE)
    plan_dir, plan, ids, done = fly_plan(base, [], day_file)
    for sid, proc in zip(ids, done):
        assert proc.returncode == 0, (sid, proc.stdout, proc.stderr)
        row = next(line for line in proc.stdout.splitlines() if "same scores as the batch simulator" in line)
        assert "yes" in row, proc.stdout  # the front-seat flew the water the plan predicted in
    logs = [base / "logs" / f"{sid}.mcap" for sid in ids]
    before = digests([day_file, *logs])
    cmp_dir = base / "comparison"
    result = runner.invoke(app, ["compare", str(plan_dir), *map(str, logs), "--out", str(cmp_dir), "--dithers", "0"])
    assert result.exit_code == 0, result.output
    out = base / "calibrated.toml"
    cal = runner.invoke(
        app,
        ["calibrate", str(day_file), *map(str, logs), "--bias", str(cmp_dir / "comparison.json"), "--out", str(out)],
    )
    assert cal.exit_code == 0, cal.output
    return {
        "plan": plan,
        "comparison": json.loads((cmp_dir / "comparison.json").read_text()),
        "compare_output": result.output,
        "calibrate_output": cal.output,
        "out": out,
        "inputs": [day_file, *logs],
        "before": before,
    }


def test_the_plan_records_the_water_it_was_made_for(day):
    water = day["plan"]["mission"]["planned_for"]["water"]
    assert water["execution_bias"] == DAY.to_dict() and water["source"] == "morning compare"


def test_compare_on_a_plan_flown_in_its_own_water_finds_a_neutral_residual(day):
    c = day["comparison"]
    assert c["day_bias"]["relative"] and c["day_bias"]["assumed"] == DAY.to_dict()
    for name, rec in c["bias"].items():
        neutral = 1.0 if name in ("speed", "current_scale", "battery") else 0.0
        if rec["identified"]:
            assert rec["estimate"] == pytest.approx(neutral, abs=max(3 * rec["stderr"], 1e-3)), name
    total = c["day_bias"]["fitted_total"]
    assert total["current_scale"] == pytest.approx(0.34, abs=0.02) and total["start_time"] == pytest.approx(
        1800, abs=60
    )
    assert "relative to it" in " ".join(day["compare_output"].split())


def test_calibrate_bias_writes_the_day_water_and_the_file_loads(day):
    m = sim.uuv.load_mission(day["out"])
    # nothing left to correct: the water stays what the plan assumed (and what the vehicle flew)
    assert m.execution_bias.current_scale == pytest.approx(0.34, abs=0.02)
    assert m.execution_bias.start_time == pytest.approx(1800.0, abs=60)
    assert m.execution_bias.speed == 1.0 and m.execution_bias.battery == 1.0  # left to the calibrated vehicle
    assert "rapt-plan compare of plan" in m.execution_bias_source
    side = json.loads(day["out"].with_suffix(".json").read_text())
    assert side["execution_bias"]["bias"] == m.execution_bias.to_dict()
    assert "[execution_bias] from rapt-plan compare" in " ".join(day["calibrate_output"].split())
    assert digests(day["inputs"]) == day["before"]  # inputs only read


def test_calibrate_bias_writes_the_noise_the_day_showed_and_the_re_plan_dithers_by_it(day):
    from planner.plan.generate import GenerateConfig

    m = sim.uuv.load_mission(day["out"])
    fitted = day["comparison"]["forecast"]["day_noise"]["fitted"]
    assert m.execution_noise is not None
    assert (m.execution_noise.position, m.execution_noise.time, m.execution_noise.battery) == pytest.approx(
        (fitted["position"], fitted["time"], fitted["battery"]), rel=1e-5
    )
    # lock-step SIL in the water the plan assumed strays less than the assumed 10 m
    assert m.execution_noise.position < 10.0 and "rapt-plan compare of plan" in m.execution_noise.source
    assert GenerateConfig().noise(m).position_m == pytest.approx(fitted["position"], rel=1e-5)
