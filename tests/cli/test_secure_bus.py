"""Every command on the range's secure bus: a whole run flies on it, its log names each channel's role,
`rapt-plan compare` accepts the log, and a bad key or role is a one-line error before anything joins."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from bridge.logger import ROLES_METADATA, read_metadata
from bridge.range_keys import make_range_keys
from planner.cli import app
from planner.review.logs import read_run
from tests.support.loopback import free_port

ROOT = Path(__file__).resolve().parents[2]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"
MISSION = ROOT / "examples" / "range2017.toml"
runner = CliRunner()


@pytest.fixture
def range_dir(tmp_path):
    """The range's keys, the hub on a free loopback port."""
    return make_range_keys(tmp_path / "keys", "uuv1", hub=f"tls/127.0.0.1:{free_port()}")


def _channel_roles(log: Path) -> dict[str, str]:
    with open(log, "rb") as f:
        channels = make_reader(f).get_summary().channels.values()
    return {c.topic: c.metadata.get("rapt.role", "") for c in channels}


@pytest.mark.slow  # a whole run over TLS and its comparison, about 18 s
@pytest.mark.integration
def test_a_run_flies_on_the_secure_bus_and_compare_accepts_its_log(range_dir, tmp_path):
    log = tmp_path / "pair2b.mcap"
    result = runner.invoke(
        app, ["run", str(PLAN), "--scenario", "pair2b", "--log", str(log), "--bus-keys", str(range_dir)]
    )
    assert result.exit_code == 0, result.output
    assert re.search(r"same scores as the batch simulator\s+│\s+yes", result.output), result.output

    roles = _channel_roles(log)  # who each channel came from: the hub's rules, per channel
    assert roles["rapt/uuv1/command/autonomy"] == "autonomy"  # the back-seat's set-points, as its own role
    assert roles["rapt/uuv1/alive/logger"] == "logger"
    assert roles["rapt/uuv1/mavlink/LOCAL_POSITION_NED"] == roles["/mavlink/raw"] == "bridge"  # the hub's own
    assert roles["rapt/uuv1/meta/scenario"] == "bridge"  # no client may put metadata
    by_key = read_metadata(log)[ROLES_METADATA]
    assert by_key["rapt/uuv1/control/active"] == "operator,watchdog"
    assert by_key["rapt/uuv1/command/autonomy"] == "autonomy"

    logged = read_run(log)
    assert logged.meta["scenario_id"] == "pair2b" and not logged.problems
    out = tmp_path / "comparison"
    compared = runner.invoke(
        app, ["compare", str(PLAN), str(log), "--out", str(out), "--dithers", "0", "--bootstrap", "0"]
    )
    assert compared.exit_code == 0, compared.output
    assert (out / "comparison.json").exists() and "100% as planned" in compared.output


def _one_line(result, expect: str) -> None:
    assert result.exit_code == 2, result.output
    assert expect in result.output, result.output
    assert "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1, result.output


def test_bad_keys_and_roles_are_one_line_before_anything_joins(range_dir, tmp_path):
    keys_dir, mission = str(range_dir), str(MISSION)
    log = ["log", "--out", str(tmp_path / "x.mcap")]
    _one_line(runner.invoke(app, [*log, "--bus-role", "logger"]), "--bus-role: only with --bus-keys")
    _one_line(runner.invoke(app, [*log, "--bus-keys", keys_dir, "--bus-role", "pilot"]), "'pilot' is not a role in")
    _one_line(
        runner.invoke(app, [*log, "--bus-keys", keys_dir, "--zenoh-config", str(range_dir / "logger.json5")]),
        "--zenoh-config: give either --bus-keys DIR or --zenoh-config FILE",
    )
    _one_line(
        runner.invoke(
            app, ["bridge", "--mavlink", "udpin:127.0.0.1:9", "--bus-keys", keys_dir, "--bus-role", "logger"]
        ),
        "--bus-role: the bridge is the hub of the secure bus, role 'bridge'",
    )
    _one_line(
        runner.invoke(app, ["autonomy", mission, "--scenario", "3", "--bus-keys", keys_dir, "--bus-role", "operator"]),
        "--bus-role: autonomy 'autonomy' puts command/autonomy, which only role 'autonomy' may",
    )
    _one_line(
        runner.invoke(app, ["run", str(PLAN), "--scenario", "pair2b", "--bus-keys", str(tmp_path / "none")]),
        "--bus-keys: ",
    )
    os.chmod(range_dir / "autonomy.key", 0o644)  # every role a run needs is checked before it starts
    _one_line(
        runner.invoke(app, ["run", str(PLAN), "--scenario", "pair2b", "--bus-keys", keys_dir]),
        f"{range_dir / 'autonomy.key'}: readable by group or others; chmod 600",
    )
