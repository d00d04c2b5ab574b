"""``rapt-plan generate``: resume, refusal to overwrite, one-line errors, and a study killed mid-search."""

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from planner.cli import app
from planner.cli.generate import straddle_line

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
runner = CliRunner()


@pytest.mark.slow  # a plan, its resume and ten refusals: about 30 s on 2 cores
def test_cli_generate_resume_and_errors(tmp_path):
    out = tmp_path / "plan"
    args = [
        "generate",
        str(EXAMPLES / "imitation7.toml"),
        "--out",
        str(out),
        "--budget",
        "600",
        "--batch-size",
        "200",
        "--dithers",
        "40",
        "--pairs",
        "2",
    ]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    assert "field plan in" in first.output and (out / "plan.json").is_file()
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and "--resume" in refused.output
    plan_before = (out / "plan.json").read_text()
    again = runner.invoke(app, args + ["--resume"])  # the stored runs are reused, not re-run
    assert again.exit_code == 0, again.output
    assert re.search(r"\d+ valid runs", again.output) and (out / "plan.json").read_text() == plan_before
    bad = tmp_path / "bad.toml"
    bad.write_text((EXAMPLES / "imitation7.toml").read_text().replace("[vehicle]", "[vehicle]\ncruize_speed = 2.0", 1))
    for argv, expect in [
        (["generate", str(bad), "--out", str(tmp_path / "x")], "cruize_speed"),
        (["generate", str(tmp_path / "none.toml"), "--out", str(tmp_path / "x")], "MISSION_FILE"),
        (["generate", str(EXAMPLES / "imitation7.toml"), "--out", str(tmp_path / "y"), "--budget", "100"], "--budget"),
        (
            ["generate", str(EXAMPLES / "range2017.toml"), "--out", str(tmp_path / "y"), "--dither-sigma", "0.4"],
            "(0, 0.25]",
        ),
        (
            ["generate", str(EXAMPLES / "range2017.toml"), "--out", str(tmp_path / "y"), "--dither-sigma", "time=600"],
            "time=600.0 is 1.00 of tx_window_start's range",
        ),
        (
            [
                "generate",
                str(EXAMPLES / "range2017.toml"),
                "--out",
                str(tmp_path / "y"),
                "--budget",
                "1000",
                "--refine",
            ],
            "--refine-runs: 160 runs for each of 10 candidate pairs leave -600 of --budget 1000",
        ),
        (
            [
                "generate",
                str(EXAMPLES / "range2017.toml"),
                "--out",
                str(tmp_path / "y"),
                "--refine",
                "--refine-runs",
                "4",
            ],
            "--refine-runs: expected at least 16 runs per pair, got 4",
        ),
    ]:
        result = runner.invoke(app, argv)
        assert result.exit_code == 2, (argv, result.output)
        assert expect in result.output and "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1


@pytest.mark.slow
def test_generate_killed_mid_search_resumes_to_the_uninterrupted_plan(tmp_path):
    import os
    import signal
    import sqlite3
    import subprocess
    import sys
    import time

    exe = Path(sys.executable).with_name("rapt-plan")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]
    args = [
        "generate",
        str(EXAMPLES / "imitation7.toml"),
        "--budget",
        "2000",
        "--batch-size",
        "250",
        "--dithers",
        "40",
        "--pairs",
        "2",
        "--refine",  # the focused searches after a resume are those of an uninterrupted run
        "--refine-runs",
        "16",
    ]
    killed = tmp_path / "killed"
    proc = subprocess.Popen(
        cmd + args + ["--out", str(killed)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        env={**os.environ, "COLUMNS": "200"},
    )
    rows, deadline = 0, time.monotonic() + 240
    try:
        while rows < 500 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            try:
                with sqlite3.connect(f"file:{killed / 'study.db'}?mode=ro", uri=True) as con:
                    rows = con.execute("SELECT COUNT(*) FROM samples").fetchone()[0]
            except sqlite3.Error:
                pass  # not created yet
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert 500 <= rows < 2000, rows  # killed mid-search, with runs stored
    resumed = runner.invoke(app, args + ["--out", str(killed), "--resume"])
    assert resumed.exit_code == 0, resumed.output
    whole = runner.invoke(app, args + ["--out", str(tmp_path / "whole")])
    assert whole.exit_code == 0, whole.output
    assert (killed / "plan.json").read_text() == (tmp_path / "whole" / "plan.json").read_text()


def test_the_summary_names_each_pair_moved_as_a_whole_after_its_p_straddle():
    plan = json.loads((EXAMPLES.parent / "field_plans" / "range2017" / "plan.json").read_text())
    plan["pairs"][1]["shifted"] = {"along": "normal", "sigmas": 1.0, "by": 0.018}
    line = straddle_line(plan)
    assert line is not None and line.startswith("P(straddle), both flown sides as predicted: pair 1 ")
    assert line.endswith(
        "; pair 2 moved as a whole 1 noise sigma across its boundary, away from its fragile side (0.018 in the unit cube)"
    )
    del plan["pairs"][1]["shifted"]
    assert "moved" not in (straddle_line(plan) or "")


def test_a_mission_with_no_boundary_is_refused_in_one_line_and_no_plan_is_written(tmp_path):
    text = (EXAMPLES / "imitation7.toml").read_text()
    # the obstacles kept off the route and the pack always full: every run succeeds the same way
    flat = text.replace('name = "imitation7"', 'name = "flatland"').replace(
        "low = -300.0\nhigh = 300.0", "low = 350.0\nhigh = 420.0"
    )
    flat = flat.replace("low = 0.05\nhigh = 0.4", "low = 0.9\nhigh = 1.0")
    assert flat.count("low = 350.0") == 3
    mission = tmp_path / "flatland.toml"
    mission.write_text(flat)
    out = tmp_path / "plan"
    result = runner.invoke(app, ["generate", str(mission), "--out", str(out), "--budget", "500"])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert len(lines) == 1 and "MISSION_FILE: no boundary to plan in flatland (valid runs by mode: TS 500)" in lines[0]
    assert sorted(p.name for p in out.iterdir()) == ["study.db"]  # no plan, no report, no scenario file
    assert mission.read_text() == flat
