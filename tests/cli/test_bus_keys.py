"""``rapt-plan bus-keys``: makes a range's keys, says where each goes, and never overwrites without --force."""

from __future__ import annotations

import stat

from typer.testing import CliRunner

from bridge.range_keys import role_config, role_names
from planner.cli import app

runner = CliRunner()


def _one_line_error(result, expect: str) -> None:
    assert result.exit_code == 2, result.output
    assert expect in result.output and "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1


def test_bus_keys_writes_each_role_and_says_where_it_goes(tmp_path):
    out = tmp_path / "range"
    args = ["bus-keys", str(out), "--vehicle", "uuv7", "--autonomy", "alpha", "--autonomy", "beta", "--days", "30"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert role_names(out) == ["alpha", "beta", "bridge", "logger", "operator", "watchdog"]
    assert stat.S_IMODE(out.stat().st_mode) == 0o700
    assert "ca.key stays with the range administrator, off the vehicle" in result.output
    assert (
        "alpha.pem, alpha.key, alpha.json5: the computer running autonomy 'alpha' (it may put only command/alpha)"
        in (result.output)
    )
    assert role_config(out, "beta") is not None


def test_an_existing_dir_is_one_line_and_exit_2_unless_force(tmp_path):
    out = tmp_path / "range"
    assert runner.invoke(app, ["bus-keys", str(out), "--vehicle", "uuv1"]).exit_code == 0
    before = (out / "ca.pem").read_bytes()
    result = runner.invoke(app, ["bus-keys", str(out), "--vehicle", "uuv1"])
    _one_line_error(result, f"DIR: '{out}' already exists and is not empty; name a new one or pass --force")
    assert (out / "ca.pem").read_bytes() == before
    assert runner.invoke(app, ["bus-keys", str(out), "--vehicle", "uuv1", "--force"]).exit_code == 0
    assert (out / "ca.pem").read_bytes() != before


def test_bad_options_are_one_line_and_exit_2(tmp_path):
    for args, expect in [
        (
            ["--hub", "tcp/127.0.0.1:7447"],
            "--hub: 'tcp/127.0.0.1:7447' is not a TLS endpoint like 'tls/127.0.0.1:7448'",
        ),
        (["--autonomy", "watchdog"], "--autonomy: 'watchdog' is named twice or is another role's name"),
        (["--days", "0"], "--days: expected a whole number of days >= 1, got 0"),
    ]:
        _one_line_error(runner.invoke(app, ["bus-keys", str(tmp_path / "k"), "--vehicle", "uuv1", *args]), expect)
    assert not (tmp_path / "k").exists()
