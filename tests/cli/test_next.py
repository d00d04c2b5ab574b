"""rapt-plan next on logs flown in lock-step SIL: boundaries confirmed, logs read once, repeats, bad logs."""

from __future__ import annotations

import json
import shutil

import pytest
from typer.testing import CliRunner

from planner.cli import app
from tests.support.sil_day import fly_plan

pytestmark = [pytest.mark.slow, pytest.mark.integration]
runner = CliRunner()


@pytest.fixture(scope="module")
def day(tmp_path_factory):
    base = tmp_path_factory.mktemp("afternoon")
    plan_dir, plan, ids, done = fly_plan(base, [])
    for sid, proc in zip(ids, done):
        assert proc.returncode == 0, (sid, proc.stdout, proc.stderr)
    return plan_dir, [base / "logs" / f"{sid}.mcap" for sid in ids]


def _next(plan_dir, logs, runs_left):
    result = runner.invoke(
        app, ["next", str(plan_dir), *map(str, logs), "--runs-left", str(runs_left), "--json"], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    return json.loads(result.output.strip().splitlines()[-1]), result.output


def test_every_side_shown_confirms_every_pair_and_next_stops(day, tmp_path):
    plan_dir, logs = day
    work = tmp_path / "plan"
    shutil.copytree(plan_dir, work)
    first, _ = _next(work, logs[:1], 5)
    assert first["next"] is not None and [p["status"] for p in first["pairs"]] == ["open", "open"]
    answer, output = _next(work, logs, 4)
    assert answer["next"] is None and answer["reason"].startswith("stop")
    assert [p["status"] for p in answer["pairs"]] == ["confirmed", "confirmed"]
    assert [p["p_confirm"] for p in answer["pairs"]] == [1.0, 1.0]
    assert "confirmed" in output
    record = json.loads((work / "afternoon.json").read_text())
    assert len(record["logs"]) == len(logs)
    assert len(record["bias"]["logs"]) == len(logs)  # every log folded into the afternoon's bias, once


def test_repeated_runs_of_a_scenario_count_towards_its_side(day, tmp_path):
    plan_dir, logs = day
    work = tmp_path / "plan"
    shutil.copytree(plan_dir, work)
    again = tmp_path / "again.mcap"
    shutil.copy(logs[0], again)  # a second run of the first scenario
    answer, _ = _next(work, [*logs, again], 0)
    assert answer["reason"].startswith("done")
    result = runner.invoke(app, ["compare", str(work), *map(str, logs), str(again), "--out", str(tmp_path / "cmp"),
                                 "--dithers", "0", "--bootstrap", "0", "--draws", "5"], env={"COLUMNS": "200"})  # fmt: skip
    assert result.exit_code == 0, result.output
    comparison = json.loads((tmp_path / "cmp" / "comparison.json").read_text())
    side = comparison["confirmation"][0]["sides"][0]
    assert side["runs"] == 2 and side["flown"][0]["frequency"] == 1.0 and side["status"] == "shown"
    assert [p["status"] for p in comparison["confirmation"]] == [p["status"] for p in answer["pairs"]]


def test_a_log_of_another_plan_is_one_line_exit_2_and_nothing_is_written(day, tmp_path):
    plan_dir, logs = day
    other = tmp_path / "other"
    shutil.copytree(plan_dir, other)
    doc = json.loads((other / "plan.json").read_text())
    doc["scenarios"][0]["u"][0] = min(1.0, doc["scenarios"][0]["u"][0] + 0.01)  # another plan: another id
    (other / "plan.json").write_text(json.dumps(doc))
    before = (other / "plan.json").read_bytes()
    result = runner.invoke(app, ["next", str(other), str(logs[1]), "--runs-left", "3"], env={"COLUMNS": "200"})
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and logs[1].name in lines[0]
    assert not (other / "afternoon.json").exists() and (other / "plan.json").read_bytes() == before
