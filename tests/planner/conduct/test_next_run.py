"""The afternoon's decision (planner.conduct.next_run.decide) on a small plan, from runs given as outcomes."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import sim.uuv
from planner.cli import app
from planner.common.plans import load_plan
from planner.conduct.next_run import afternoon, decide
from planner.plan.generate import GenerateConfig, generate
from planner.review.confirmations import RunOutcome, side_scenarios
from tests.support.sil_day import MISSION

runner = CliRunner()


@pytest.fixture(scope="module")
def plan_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("conduct") / "plan"
    generate(
        sim.uuv.load_mission(MISSION), MISSION, out, GenerateConfig(budget=500, batch_size=250, dithers=20, pairs=2)
    )
    return out


def _outcome(day, sid: str) -> RunOutcome:
    return RunOutcome(sid, np.asarray(day.predicted[sid]), f"{sid}.mcap")


def test_a_side_that_came_out_against_is_flown_again_or_moved_into_the_plan(plan_dir, tmp_path):
    work = tmp_path / "plan"
    work.mkdir()
    for f in plan_dir.iterdir():
        if f.is_file():
            (work / f.name).write_bytes(f.read_bytes())
    plan = load_plan(work)
    before = plan.id
    day = afternoon(plan, [])
    (a1, b1), (a2, b2) = (p["scenarios"] for p in plan.pairs)
    wrong = RunOutcome(b1, np.asarray(day.predicted[a1]), "miss.mcap")  # side b showed side a's outcome, twice
    runs = [_outcome(day, a1), wrong, wrong, _outcome(day, a2), _outcome(day, b2)]
    answer = decide(afternoon(plan, runs), 4)
    assert [p["status"] for p in answer["pairs"]][1] == "confirmed"
    assert answer["confirmation"][0]["sides"][1]["status"] == "against"
    chosen = answer["next"]["scenario"]
    after = load_plan(work)
    assert chosen in side_scenarios(after, b1)
    assert "pair 1's b side" in answer["reason"]
    if chosen not in side_scenarios(plan, b1):  # moved: a new variant with its range files and origin
        entry = next(v for v in after.variants if v["id"] == chosen)
        assert entry["variant_of"] == b1 and entry["origin"]["by"] == "rapt-plan next"
        assert entry["origin"]["reason"] == answer["reason"] and "moved" in answer["reason"]
        assert all((work / name).is_file() for name in entry["files"].values())
        assert chosen in json.loads((work / "plan.json").read_text())["run_order"]
    assert after.id == before  # the logs flown before still belong to the plan
    json.dumps({k: answer[k] for k in ("next", "reason", "pairs")})


def test_the_day_is_done_with_no_runs_left_and_every_pair_unflown_is_open(plan_dir, tmp_path):
    work = tmp_path / "plan"
    work.mkdir()
    for f in plan_dir.iterdir():
        if f.is_file():
            (work / f.name).write_bytes(f.read_bytes())
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
    work = tmp_path / "plan"
    work.mkdir()
    for f in plan_dir.iterdir():
        if f.is_file():
            (work / f.name).write_bytes(f.read_bytes())
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
    assert not Path(plan_dir / "afternoon.json").exists()
