"""`rapt-plan shakedown` refuses, in one line and writing nothing, a range its calibration run cannot fit."""

from __future__ import annotations

from pathlib import Path

import pytest
from typer.testing import CliRunner

from planner.cli import app
from sim.uuv.missionfile import load_mission_text

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
runner = CliRunner()


def test_it_writes_the_plan_and_prints_the_legs(tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(
        app, ["shakedown", str(EXAMPLES / "imitation7.toml"), "--out", str(out)], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    assert (out / "plan.json").is_file() and "turn_left" in result.output and "ends recovered" in result.output


def _imitation7(old: str, new: str) -> str:
    text = (EXAMPLES / "imitation7.toml").read_text()
    assert old in text
    return text.replace(old, new)


@pytest.mark.parametrize(
    "text, expect",
    [
        (  # the launch point 30 m from the southern edge of a smaller area
            _imitation7("width = 1000.0\nheight = 1000.0", "width = 700.0\nheight = 860.0"),
            "leaves the operational area (1 m out) (margin 50 m); give the launch point more room",
        ),
        (  # a no-go band across the range, 40 m north of the launch point
            _imitation7(
                "[[waypoints]]",
                '[[nogo]]\nname = "Z"\nx = 0.0\ny = -310.0\nwidth = 1000.0\nheight = 100.0\n\n[[waypoints]]',
            ),
            "crosses no-go area Z (49 m deep) (margin 50 m); move no-go area Z",
        ),
    ],
)
def test_a_range_it_cannot_fit_is_one_line_and_writes_nothing(tmp_path, text, expect):
    path = tmp_path / "mission.toml"
    path.write_text(text)
    load_mission_text(text, str(path))  # a valid mission: only the calibration run cannot fit
    out = tmp_path / "out"
    result = runner.invoke(app, ["shakedown", str(path), "--out", str(out)])
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert "no calibration run fits mission 'imitation7'" in lines[0] and expect in lines[0], lines[0]
    assert not out.exists() and path.read_text() == text


def test_options_out_of_range_are_one_line():
    result = runner.invoke(app, ["shakedown", str(EXAMPLES / "range2017.toml"), "--out", "x", "--max-minutes", "5"])
    lines = [line for line in result.output.splitlines() if line.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and "--max-minutes" in lines[0], result.output
    assert not Path("x").exists()
