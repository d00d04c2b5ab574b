"""rapt-plan next's command line without logs: the start and end of an afternoon, and input it refuses."""

from __future__ import annotations

import json
import subprocess

import pytest
from typer.testing import CliRunner

from planner.cli import app
from planner.common.plans import load_plan
from planner.review.confirmations import side_scenarios
from tests.support.small_plan import plan_copy

runner = CliRunner()


@pytest.fixture
def plan_dir(small_plan_dir):
    return small_plan_dir


def test_the_day_is_done_with_no_runs_left_and_every_pair_unflown_is_open(plan_dir, tmp_path):
    work = plan_copy(plan_dir, tmp_path / "plan")
    result = runner.invoke(app, ["next", str(work), "--runs-left", "0", "--json"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    last = json.loads(result.output.strip().splitlines()[-1])
    assert last["next"] is None and last["reason"].startswith("done")
    assert [p["status"] for p in last["pairs"]] == ["open", "open"]
    result = runner.invoke(app, ["next", str(work), "--runs-left", "6", "--json"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    first = json.loads(result.output.strip().splitlines()[-1])
    assert "not flown yet" in first["reason"]
    plan = load_plan(work)
    assert any(first["next"]["scenario"] in side_scenarios(plan, s) for p in plan.pairs for s in p["scenarios"])


def test_a_plan_directory_that_cannot_be_written_is_one_line_before_anything_else(plan_dir, tmp_path):
    work = plan_copy(plan_dir, tmp_path / "plan")
    subprocess.run(["chattr", "+i", str(work / "plan.json"), str(work)], check=True)
    try:
        result = runner.invoke(app, ["next", str(work), "missing.mcap", "--runs-left", "3"], env={"COLUMNS": "200"})
    finally:
        subprocess.run(["chattr", "-i", str(work / "plan.json"), str(work)], check=True)
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and "cannot be written" in lines[0] and "PLAN" in lines[0]
    assert not (work / "afternoon.json").exists()


def test_a_negative_runs_left_is_refused(plan_dir):
    result = runner.invoke(app, ["next", str(plan_dir), "--runs-left", "-1"], env={"COLUMNS": "200"})
    assert result.exit_code == 2 and "--runs-left" in result.output
    assert not (plan_dir / "afternoon.json").exists()
