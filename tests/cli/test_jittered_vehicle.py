"""A vehicle whose reports jitter and get lost, flown as on a range day: compare and calibrate accept its logs.

`rapt-plan frontseat PLAN --scenario ID --bare --jitter 0.25 [--drop-reports 0.1] --seed N`
is the vehicle (a process of its own); the range-day stack flies it through ``--mavlink`` on
loopback MAVLink and a real Zenoh session (:func:`planner.fly.vehicle.run.run_vehicle`) for a
bounded wall time; `rapt-plan compare` and the calibration then read the two logs.  Before
issue 38 both refused them: "no replayable flight in the logs".
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from planner.cli import app
from planner.fly.flight import flight_from_plan
from planner.fly.vehicle.run import run_vehicle
from planner.review.calibrate import calibrate
from planner.review.logs import read_run
from planner.review.segments import replayable_steps
from tests.support.loopback import free_port

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
MISSION = ROOT / "examples" / "range2017.toml"
SPEEDUP = 25.0
WALL_S = 25.0
runner = CliRunner()


def _fly(sid: str, log: Path, *timing: str) -> str:
    """Fly plan scenario ``sid`` on the bare front-seat with the report ``timing`` options; how the run ended."""
    port = free_port(socket.SOCK_DGRAM)
    vehicle = subprocess.Popen(
        [sys.executable, "-m", "planner.cli", "frontseat", str(PLAN), "--scenario", sid]
        + ["--mavlink", f"udpin:127.0.0.1:{port}", "--bare", "--speedup", str(SPEEDUP), *timing],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        result = run_vehicle(
            flight_from_plan(PLAN, sid), f"udpout:127.0.0.1:{port}", log_path=log, timeout_s=WALL_S, guard=None
        )
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, err = vehicle.communicate(timeout=30)
    assert vehicle.returncode in (0, 130, -signal.SIGINT), err
    return result.ended


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    base = tmp_path_factory.mktemp("jittered")
    jittered, dropped = base / "pair1a.mcap", base / "pair2a.mcap"
    ended = [
        _fly("pair1a", jittered, "--jitter", "0.25", "--seed", "1"),
        _fly("pair2a", dropped, "--jitter", "0.25", "--drop-reports", "0.1", "--seed", "2"),
    ]
    return base, [jittered, dropped], ended


@pytest.mark.slow
@pytest.mark.integration
def test_logs_of_a_jittered_vehicle_are_compared_and_calibrated(logs):
    base, paths, ended = logs
    assert all(ended), ended  # the wall-time limit, or on a starved machine the watchdog (stale commands)
    for p in paths:
        run = read_run(p)
        steps = np.diff(run.steps[:, 0])
        assert run.steps.shape[0] > 60, p.name  # two minutes of the vehicle's time at least
        assert np.mean(np.abs(steps - 2.0) < 1e-6) < 0.2, p.name  # the vehicle's times, seldom on the period
        assert replayable_steps(run, 2.0).mean() > 0.9, p.name
    out = base / "comparison"
    result = runner.invoke(
        app, ["compare", str(PLAN), *map(str, paths), "--out", str(out), "--dithers", "0", "--bootstrap", "0"]
    )
    assert result.exit_code == 0, result.output
    fit = json.loads((out / "comparison.json").read_text())
    assert fit["bias_fit"]["runs"] == 2 and fit["bias_fit"]["segments"] >= 8
    assert fit["bias"]["speed"]["estimate"] == pytest.approx(
        1.0, abs=0.05
    )  # no bias injected: the vehicle is the model
    cal = calibrate(MISSION, paths, base / "calibrated.toml", fit=("speed_gain", "drag_w"), bootstrap=0)
    assert cal.runs == 2 and cal.segments >= 8
    assert cal.vehicle.speed_gain == pytest.approx(1.0, abs=0.05)


def test_report_timing_options_are_refused_without_bare_or_out_of_range():
    for args, expect in (
        (["--jitter", "0.25"], "--jitter: only with --bare"),
        (["--bare", "--jitter", "-1"], "--jitter: expected vehicle seconds >= 0"),
        (["--bare", "--drop-reports", "1"], "--drop-reports: expected a share of reports in [0, 1)"),
    ):
        result = runner.invoke(app, ["frontseat", str(MISSION), "--mavlink", "udpin:127.0.0.1:9", *args])
        lines = [ln for ln in result.output.splitlines() if ln.strip()]
        assert result.exit_code == 2 and len(lines) == 1 and expect in lines[0], result.output
