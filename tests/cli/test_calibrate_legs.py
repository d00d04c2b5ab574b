"""rapt-plan calibrate on a calibration run whose legs were cut short: one line, or written when told to keep."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from planner.cli import app
from planner.review.calibration_terms import term_need
from tests.planner.review.test_calibration_legs import cut_run, fake_log, fly_legs, thruster_missions


@pytest.fixture(scope="module")
def missions(tmp_path_factory):
    return thruster_missions(tmp_path_factory.mktemp("thruster"))


@pytest.fixture(scope="module")
def flown(missions):
    return fly_legs(missions[1], missions[2].vehicle)


@pytest.mark.slow
def test_the_command_refuses_in_one_line_and_names_what_is_kept_when_told(missions, flown, tmp_path, monkeypatch):
    file_path, _, _ = missions
    run, _, _ = flown
    cut = cut_run(run, 480.0, [{"source": "watchdog", "event": "intervention", "reason": "battery"}])
    log = fake_log(tmp_path, monkeypatch, cut)
    out = tmp_path / "cli.toml"
    runner = CliRunner()
    refused = runner.invoke(app, ["calibrate", str(file_path), str(log), "--out", str(out)])
    lines = [ln for ln in refused.output.splitlines() if ln.strip()]
    assert refused.exit_code == 2 and len(lines) == 1 and "--keep-unidentified" in lines[0], refused.output
    assert not out.exists()
    kept = runner.invoke(app, ["calibrate", str(file_path), str(log), "--out", str(out), "--keep-unidentified"])
    assert kept.exit_code == 0, kept.output
    assert (
        f"to identify speed_curve[1.8]: {term_need('speed_curve[1.8]')[0]}" in kept.output
        and "watchdog took over: battery" in kept.output
    )
    assert out.exists()
