"""rapt-plan calibrate on real lock-step SIL logs: a deliberately wrong vehicle block recovered, bad inputs refused.

One small plan (2 pairs of the 2017 range mission, 4 scenarios) is flown in SIL with the
true vehicle — `rapt-plan run PLAN --scenario ID --log`, two runs at a time — and the
logs calibrate a copy of the mission whose [vehicle] block is 20-40 % off.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

import sim.uuv
from planner.cli import app
from planner.review.logs import read_run
from planner.review.vehicle_fit import FITTED, MIN_LOGS, SLOW_TERMS
from sim.uuv.replay import score_track
from sim.uuv.scoring import MODE_NAMES, mode_name
from tests.planner.review.test_calibrate import wrong_mission_text
from tests.support.sil_day import MISSION, digests, fly_plan

runner = CliRunner()


def _one_line_error(result, expect: str) -> None:
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and expect in lines[0], result.output


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    base = tmp_path_factory.mktemp("calibration_day")
    plan_dir, plan, ids, done = fly_plan(base, [])
    logs_dir = base / "logs"
    for sid, proc in zip(ids, done):
        assert proc.returncode == 0, (sid, proc.stdout, proc.stderr)
    wrong = base / "wrong.toml"
    wrong.write_text(wrong_mission_text())
    logs = [logs_dir / f"{sid}.mcap" for sid in ids]
    inputs = [wrong, *logs]
    before = digests(inputs)
    out = base / "calibrated.toml"
    result = runner.invoke(app, ["calibrate", str(wrong), *map(str, logs), "--out", str(out)])
    assert result.exit_code == 0, result.output
    return {"base": base, "wrong": wrong, "logs": logs, "out": out, "output": result.output, "before": before}


@pytest.mark.slow
def test_calibrate_recovers_the_true_vehicle_block_from_sil_logs(flown):
    true = sim.uuv.load_mission(MISSION).vehicle
    side = json.loads(flown["out"].with_suffix(".json").read_text())
    cal = sim.uuv.load_mission(flown["out"])
    # a torpedo's speed loop: the surge loop stands and no slow part is fitted
    assert side["velocity_control"]["value"] == "surge" and not set(SLOW_TERMS) & set(side["parameters"])
    for n in (n for n in FITTED if n not in SLOW_TERMS):
        p = side["parameters"][n]
        # the autonomy never asks for more than the vehicle reaches (below or at the surface); the lock-step
        # front-seat surfaces within a step
        if n in ("max_speed", "ascent_rate_mps", "surface_max_speed"):
            assert p["identified"] is False and getattr(cal.vehicle, n) == p["file_value"]
            continue
        if n == "surface_power_w":  # it draws nothing more at the surface: the file's 0 stands
            assert p["identified"] and getattr(cal.vehicle, n) == 0.0 and abs(p["map_estimate"]) < 3 * p["stderr"]
            continue
        assert p["identified"], n
        assert getattr(cal.vehicle, n) == pytest.approx(getattr(true, n), rel=0.1), n
        assert p["stderr"] < 0.05 * getattr(true, n), n
    assert side["residual_rms"]["after"]["position_m"] < 0.05 * side["residual_rms"]["before"]["position_m"]
    for word in (
        "[vehicle] calibrated from 4 run(s)",
        "surge_time_constant_s",
        "drag_w",
        "file value kept: max_speed",
        "calibrated.json written",
    ):
        assert word in flown["output"], flown["output"]


@pytest.mark.slow
def test_no_input_is_modified_and_the_output_predicts_the_logged_modes(flown):
    assert digests(flown["before"]) == flown["before"]
    cal = sim.uuv.load_mission(flown["out"])
    runs = [read_run(p) for p in flown["logs"]]
    U = np.array([r.meta["u"] for r in runs])
    observed = [mode_name(score_track(cal, u, r.track, r.wp_aborted, r.return_reason)) for u, r in zip(U, runs)]
    assert all(r.has_end for r in runs)
    assert [MODE_NAMES[k] for k in sim.uuv.simulate(cal, U).modes] == observed


@pytest.mark.slow
def test_too_few_logs_another_mission_and_an_out_over_an_input_are_one_line_errors(flown, tmp_path):
    wrong, logs = flown["wrong"], flown["logs"]
    before = digests([wrong, *logs])
    out = tmp_path / "c.toml"
    _one_line_error(
        runner.invoke(app, ["calibrate", str(wrong), *map(str, logs[: MIN_LOGS - 1]), "--out", str(out)]),
        f"LOGS: {MIN_LOGS - 1} log(s) given; a calibration needs at least {MIN_LOGS} runs",
    )
    other = tmp_path / "other.toml"
    other.write_text(wrong.read_text().replace('name = "range2017"', 'name = "range2018"'))
    _one_line_error(
        runner.invoke(app, ["calibrate", str(other), *map(str, logs), "--out", str(out)]),
        f"LOG: {logs[0].name} was flown on mission 'range2017', but other.toml is mission 'range2018'",
    )
    _one_line_error(
        runner.invoke(app, ["calibrate", str(wrong), *map(str, logs), "--out", str(wrong)]),
        "would overwrite an input",
    )
    assert not out.exists() and digests([wrong, *logs]) == before


def test_a_missing_log_or_mission_is_a_one_line_error(tmp_path):
    _one_line_error(
        runner.invoke(app, ["calibrate", str(MISSION), str(tmp_path / "a.mcap"), str(tmp_path / "b.mcap")]),
        f"LOGS: {tmp_path / 'a.mcap'} does not exist",
    )
    _one_line_error(
        runner.invoke(app, ["calibrate", str(tmp_path / "m.toml"), str(MISSION), str(MISSION)]),
        "MISSION: ",
    )
