"""The `rapt-plan` commands as a user runs them: output, exit codes, one-line errors, processes that stop cleanly."""

import json
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from planner.cli import app

runner = CliRunner()
RANGE2017 = str(Path(__file__).resolve().parents[2] / "examples" / "range2017.toml")


def test_search_prints_quality_against_sobol(tmp_path):
    db = tmp_path / "study.db"
    result = runner.invoke(app, ["search", "plates2d", "--budget", "600", "--store", str(db)])
    assert result.exit_code == 0, result.output
    assert "plates2d: 600 samples, D_eps = 0.01" in result.output
    rows = {m.group(1): float(m.group(2)) for m in re.finditer(r"│ (s-ndv|sobol)\s+│\s+([\d.]+)%", result.output)}
    assert rows["s-ndv"] > 2.5 * rows["sobol"]
    assert db.exists() and "600 rows" in result.output
    again = runner.invoke(app, ["search", "plates2d", "--budget", "600", "--store", str(db)])
    assert again.exit_code == 0 and again.output.count("s-ndv") == result.output.count("s-ndv")


def test_bad_input_is_one_line_and_exit_2():
    for args, expect in [
        (["search", "plates9d"], "SYSTEM: unknown system 'plates9d'"),
        (["search", "plates2d", "--budget", "50"], "budget: 50 is smaller than batch_size 100"),
        (["search", "plates2d", "--method", "lola"], "method: unknown method 'lola'"),
        (["search", "plates2d", "--baseline", "grid"], "--baseline: unknown method 'grid'"),
        (["search", "plates2d", "--d-eps", "0"], "--d-eps: must be > 0"),
    ]:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert expect in result.output
        assert "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1


def test_rapt_traceback_shows_where_an_error_came_from(monkeypatch):
    """RAPT_TRACEBACK=1: the same one-line error and exit code, after the traceback of the exception behind it."""
    monkeypatch.setenv("RAPT_TRACEBACK", "1")
    result = runner.invoke(app, ["search", "plates2d", "--budget", "50"])
    assert result.exit_code == 2, result.output
    assert "Traceback (most recent call last)" in result.output
    assert result.output.strip().splitlines()[-1].startswith("error: ") and "budget: 50" in result.output


def test_study_of_a_mission_reports_modes_and_boundary_types(tmp_path):
    db = tmp_path / "study.db"
    args = ["study", RANGE2017, "--budget", "1000", "--batch-size", "250", "--store", str(db)]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "range2017: 1000 scenarios (15-D)" in result.output
    shares = {m.group(1): float(m.group(2)) for m in re.finditer(r"mode (TF|SS|MS|TS)\s+│\s+([\d.]+)%", result.output)}
    assert set(shares) == {"TF", "SS", "MS", "TS"} and sum(v > 0 for v in shares.values()) >= 3
    assert "boundary TF/SS" in result.output and "1000 scenarios)" in result.output
    again = runner.invoke(app, args)  # resumed from the store: same table
    assert again.exit_code == 0
    assert again.output.split("time (s)")[0] == result.output.split("time (s)")[0]


def test_study_bad_mission_is_one_line_and_exit_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[mission]\nname = "x"\nbogus = 1\n')
    for args, expect in [
        (["study", str(tmp_path / "missing.toml")], "MISSION_FILE: "),
        (["study", str(bad)], f"{bad}: "),
        (["study", RANGE2017, "--baseline", "grid"], "--baseline: unknown method"),
    ]:
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        assert expect in result.output and "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1


@pytest.mark.integration
def test_run_flies_a_scenario_in_the_loop_and_logs_it(tmp_path):
    log = tmp_path / "run.mcap"
    result = runner.invoke(app, ["run", RANGE2017, "--scenario", "3", "--log", str(log)])
    assert result.exit_code == 0, result.output
    assert re.search(r"same scores as the batch simulator\s+│\s+yes", result.output)
    from bridge.logger import read_log, read_metadata

    topics = {t for t, _, _ in read_log(log)}
    assert {"rapt/uuv1/mavlink/LOCAL_POSITION_NED", "rapt/uuv1/command/autonomy"} <= topics
    assert read_metadata(log)["scenario"]["scenario_id"] == "sobol-3"
    # the run itself was sound: no automatic check of its log fails (the simulated front-seat streams no
    # SERVO_OUTPUT_RAW, and its pack is the scenario's battery, run low by this scenario: no more than warnings)
    checked = runner.invoke(app, ["check", str(log), "--json"])
    assert checked.exit_code == 0, checked.output
    checks = json.loads(checked.output)["run.mcap"]
    from planner.review.run_checks import CHECKS

    assert [c["name"] for c in checks] == list(CHECKS)
    verdicts = {c["name"]: c["verdict"] for c in checks}
    assert "fail" not in verdicts.values(), checks
    for name in ("estimator", "position", "link", "setpoints", "depth", "statustext", "modes"):
        assert verdicts[name] == "pass", checks


@pytest.mark.integration
@pytest.mark.parametrize("bus", ["loopback", pytest.param("secure", marks=pytest.mark.slow)])
def test_each_piece_runs_as_its_own_process_and_stops_cleanly(tmp_path, bus):
    """Bridge, logger, autonomy and front-seat as processes, on the loopback bus or on the range's
    secure bus (``--bus-keys``: mutual TLS, each as its role; the front-seat speaks only MAVLink)."""
    import signal
    import socket
    import subprocess
    import sys
    import time

    def port(kind):
        with socket.socket(socket.AF_INET, kind) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]

    udp, hub = port(socket.SOCK_DGRAM), port(socket.SOCK_STREAM)
    log = tmp_path / "bus.mcap"
    cli = [sys.executable, "-m", "planner.cli"]
    zen = ["--zenoh-connect", f"tcp/127.0.0.1:{hub}"]
    listen = ["--zenoh-listen", f"tcp/127.0.0.1:{hub}"]
    if bus == "secure":
        from bridge.range_keys import make_range_keys

        zen = listen = ["--bus-keys", str(make_range_keys(tmp_path / "keys", "uuv1", hub=f"tls/127.0.0.1:{hub}"))]
    procs = [
        subprocess.Popen(cli + ["bridge", "--mavlink", f"udpout:127.0.0.1:{udp}", *listen, "--allow-commands", "--arm"])
    ]
    # No pause: the clients wait for the hub (bridge.session.CONNECT_TIMEOUT_S), in any start order.
    procs += [
        subprocess.Popen(cli + ["log", "--out", str(log)] + zen),
        subprocess.Popen(cli + ["autonomy", RANGE2017, "--scenario", "3"] + zen),
        subprocess.Popen(cli + ["frontseat", RANGE2017, "--scenario", "3", "--mavlink", f"udpin:127.0.0.1:{udp}"]),
    ]
    from bridge.logger import read_log

    def flown() -> tuple[list, list]:
        try:
            rows = read_log(log)
        except Exception:  # not written yet
            return [], [0.0]
        north = [m["x"] for t, _, m in rows if t == "rapt/uuv1/mavlink/LOCAL_POSITION_NED"] or [0.0]
        return [m for t, _, m in rows if t == "rapt/uuv1/command/autonomy"], north

    try:
        deadline = time.monotonic() + 90  # a loaded machine starts four Pythons slowly
        while time.monotonic() < deadline:
            assert all(p.poll() is None for p in procs), [p.returncode for p in procs]
            commands, north = flown()
            if len(commands) > 50 and max(north) - min(north) > 50:
                break
            time.sleep(1.0)
    finally:
        for p in reversed(procs):
            p.send_signal(signal.SIGINT)
        codes = [p.wait(timeout=20) for p in procs]
    assert codes == [0, 0, 0, 0]
    commands, north = flown()
    assert len(commands) > 50 and max(north) - min(north) > 50  # the autonomy flew the vehicle
    from tests.support.foxglove_check import foxglove_channels

    maps = foxglove_channels(log)["/map/scenario"].messages  # from the autonomy, whichever started first
    assert len(maps) == 1 and "predicted_track" in maps[0]["geojson"]
    if bus == "secure":  # rapt-plan log names each channel's role, from the roles in DIR
        from mcap.reader import make_reader

        with open(log, "rb") as f:
            roles = {c.topic: c.metadata.get("rapt.role") for c in make_reader(f).get_summary().channels.values()}
        assert roles["rapt/uuv1/command/autonomy"] == "autonomy" and roles["/mavlink/raw"] == "bridge"


def test_selfright_is_a_rapt_plan_command_with_one_line_errors(tmp_path):
    bad = tmp_path / "robot.toml"
    bad.write_text("[robot]\nname = 'x'\n")
    result = runner.invoke(app, ["selfright", str(bad), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1
    robot = str(Path(__file__).resolve().parents[2] / "examples" / "robots" / "1dof.toml")
    result = runner.invoke(app, ["selfright", robot, "--out", str(tmp_path / "out"), "--slope", "95"])
    assert result.exit_code == 2 and "--slope" in result.output


def test_a_rapt_error_no_command_caught_is_still_one_line_and_exit_2(monkeypatch, capsys):
    """The rapt-plan script's last line of defence: an error class a command did not expect prints no traceback."""
    import planner.cli
    from rapt.errors import RunError

    def broken(*args, **kwargs):
        raise RunError("front-seat: the simulator stopped answering; run it again")

    monkeypatch.setattr(planner.cli.search, "run_search", broken)
    monkeypatch.setattr("sys.argv", ["rapt-plan", "search", "plates2d", "--budget", "100"])
    with pytest.raises(SystemExit) as exit_info:
        planner.cli.rapt_plan()
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert err.strip() == "error: front-seat: the simulator stopped answering; run it again"


def test_an_invalid_scenario_names_its_reason_and_valid_ones():
    """Row 0 of range2017 puts a no-go area on mission area B; the error says so and offers valid rows."""
    for command in (["frontseat", RANGE2017, "--mavlink", "udpin:127.0.0.1:9"], ["run", RANGE2017]):
        result = runner.invoke(app, command + ["--scenario", "0"])
        assert result.exit_code == 2, result.output
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert lines == [
            "error: --scenario: scenario 0 is invalid for mission 'range2017' "
            "(a no-go area on the centre of mission area B); valid ones include 1, 2, 3"
        ]
    plan = Path(__file__).resolve().parents[2] / "field_plans" / "range2017"
    result = runner.invoke(app, ["frontseat", str(plan), "--mavlink", "udpin:127.0.0.1:9"])
    assert result.exit_code == 2 and "--scenario: name the scenario of" in result.output
    assert "choose one of pair1a, pair1b" in result.output


@pytest.mark.integration
def test_frontseat_without_scenario_serves_the_first_valid_one(tmp_path):
    """`rapt-plan frontseat MISSION --mavlink ...` with no --scenario: a heartbeat on loopback, row 1 named."""
    import os
    import signal
    import socket
    import subprocess
    import sys
    import time

    os.environ["MAVLINK20"] = "1"  # before pymavlink is imported (CONVENTIONS 2g)
    from pymavlink import mavutil

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        udp = s.getsockname()[1]
    proc = subprocess.Popen(
        [sys.executable, "-m", "planner.cli", "frontseat", RANGE2017, "--mavlink", f"udpin:127.0.0.1:{udp}"],
        stderr=subprocess.PIPE,
        text=True,
        env={**os.environ, "COLUMNS": "200"},
    )
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{udp}", source_system=255)
    try:
        heard, deadline = None, time.monotonic() + 30
        while heard is None and time.monotonic() < deadline and proc.poll() is None:
            gcs.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            heard = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
    finally:
        gcs.close()
        proc.send_signal(signal.SIGINT)
        _, stderr = proc.communicate(timeout=20)
    assert heard is not None and heard.type == mavutil.mavlink.MAV_TYPE_SUBMARINE, stderr
    assert proc.returncode == 0, stderr
    assert f"front-seat: mission 'range2017' scenario sobol-1 on udpin:127.0.0.1:{udp}" in stderr


def test_compare_refuses_draws_below_one_before_reading_anything(tmp_path):
    log = tmp_path / "run.mcap"
    log.write_text("not read\n")
    result = runner.invoke(app, ["compare", str(tmp_path / "plan"), str(log), "--draws", "0", "--out", str(tmp_path)])
    assert result.exit_code == 2, result.output
    assert "--draws: expected a number of runs >= 1, got 0" in result.output and "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1
    assert sorted(tmp_path.iterdir()) == [log]


def test_a_live_view_port_in_use_is_one_line_and_exit_2(tmp_path):
    import socket

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        result = runner.invoke(app, ["run", RANGE2017, "--scenario", "3", "--foxglove", str(port)])
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.splitlines() if line.strip() and not line.startswith("live view:")]
    assert lines == [f"error: --foxglove: port {port} on 127.0.0.1 is in use; give another port or stop what holds it"]
    bad = runner.invoke(app, ["log", "--out", str(tmp_path / "x.mcap"), "--foxglove", "host:port"])
    assert bad.exit_code == 2 and "--foxglove: expected [HOST:]PORT" in bad.output
    assert not (tmp_path / "x.mcap").exists()
