"""A plan's scenario flown on a vehicle we do not simulate in lock-step: our front-seat as a bare ArduSub.

The vehicle keeps its own pace (speed-up 25), streams at its own rates, has no sonar and
refuses GUIDED until its estimator is ready; the whole range-day stack flies it through
``--mavlink`` on loopback MAVLink and a real Zenoh session.  Each test starts and stops its
vehicle; no process, socket or thread outlives it.
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

import sim.uuv
from planner.fly.flight import Flight, flight_from_plan
from planner.fly.vehicle.run import run_vehicle
from planner.review.logs import read_run
from sim.uuv.geometry import polygon_signed_distance
from sim.uuv.missionfile import load_mission
from sim.uuv.scenario import make_scenarios
from tests.support.bare_vehicle import SPEEDUP, bare_vehicle
from tests.support.foxglove_check import check_channel, foxglove_channels
from tests.support.loopback import free_port

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[4]
PLAN = ROOT / "field_plans" / "range2017" / "plan.json"


def _rapt_plan() -> list[str]:
    exe = Path(sys.executable).with_name("rapt-plan")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]


def _nogo_scenario() -> str:
    """The plan's scenario (or variant) predicted TF that enters a no-go area soonest: the watchdog ends it there."""
    from sim.uuv.scenario import make_scenarios

    plan = json.loads(PLAN.read_text())
    mission = sim.uuv.load_mission(ROOT / "examples" / "range2017.toml")
    tf = [s for s in plan["scenarios"] + plan["variants"] if s["predicted"]["mode"] == "TF"]
    U = np.array([s["u"] for s in tf])
    runs, rects = sim.uuv.simulate(mission, U, trajectories=True), make_scenarios(mission, U).nogo
    entry = {}
    for k, s in enumerate(tf):
        t, x, y = (runs.trajectory(k)[:, c] for c in range(3))
        inside = np.any(
            (rects[k, :, 0] <= x[:, None])
            & (x[:, None] <= rects[k, :, 1])
            & (rects[k, :, 2] <= y[:, None])
            & (y[:, None] <= rects[k, :, 3]),
            axis=1,
        )
        if inside.any():
            entry[s["id"]] = float(t[np.argmax(inside)])
    return min(entry, key=entry.__getitem__)


@pytest.mark.slow
def test_an_operators_range_day_on_a_bare_autopilot_is_accepted_by_compare(tmp_path):
    """`rapt-plan frontseat --bare` stands in for the vehicle; `rapt-plan run --mavlink --log` flies on it the
    plan's scenario where a no-go area is predicted entered: the watchdog takes over there and ends the run;
    `rapt-plan compare` reads the log like a SIL one and finds the predicted mode.  The vehicle boots at the
    launch point and drifts with the current, disarmed, for as long as the run takes to start (seconds on a
    busy machine, a minute or more of vehicle time at speed-up 25): `--transit` brings it back to the start, as a
    crew would."""
    sid = _nogo_scenario()
    port = free_port(socket.SOCK_DGRAM)
    env = {**os.environ, "COLUMNS": "200"}
    vehicle = subprocess.Popen(
        _rapt_plan()
        + ["frontseat", str(PLAN), "--scenario", sid, "--mavlink", f"udpin:127.0.0.1:{port}"]
        + ["--bare", "--speedup", str(SPEEDUP)],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    log = tmp_path / f"{sid}.mcap"
    try:
        run = subprocess.run(
            _rapt_plan()
            + [
                "run",
                str(PLAN),
                "--scenario",
                sid,
                "--mavlink",
                f"udpout:127.0.0.1:{port}",
                "--log",
                str(log),
                "--no-guard",
                "--transit",
            ]
            + ["--timeout", "150"],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=240,
        )
    finally:
        vehicle.send_signal(signal.SIGINT)
        vehicle.communicate(timeout=30)
    assert run.returncode == 0, run.stderr + run.stdout
    steps = "heartbeat streams estimate area start guard mission guided arm depth clock"
    for step in steps.split():
        assert f" {step} " in run.stderr, run.stderr  # the bring-up, step by step, as it happens
    assert run.stderr.index(" depth ") < run.stderr.index(" clock "), run.stderr
    assert " transit " not in run.stderr or run.stderr.index(" transit ") < run.stderr.index(" clock "), run.stderr
    assert "watchdog: nogo" in run.stdout, run.stdout
    observed = next(line for line in run.stdout.splitlines() if "observed mode" in line)
    assert "TF" in observed, run.stdout  # the plan's prediction: a no-go area entered

    logged = read_run(log)
    assert logged.ended == "watchdog: nogo" and logged.meta["pacing"] == "vehicle" and not logged.problems
    sources = {e["source"]: e for e in logged.events}
    assert {"bringup", "referee", "watchdog"} <= set(sources)
    assert sources["watchdog"]["event"] == "intervention" and sources["watchdog"]["reason"] == "nogo"
    # what Foxglove shows unconfigured: the vehicle on the map over the scenario, the watchdog in the log
    channels = foxglove_channels(log)
    assert {"/vehicle/fix", "/map/scenario", "/vehicle/log", "/vehicle/tf", "/vehicle/track_local"} <= set(channels)
    for channel in channels.values():
        check_channel(channel)
    kinds = {f["properties"]["kind"] for f in json.loads(channels["/map/scenario"].messages[0]["geojson"])["features"]}
    assert {"nogo", "mission_area", "predicted_track"} <= kinds
    assert any(m["name"] == "watchdog" and m["level"] == 4 for m in channels["/vehicle/log"].messages)  # ERROR
    out = tmp_path / "comparison"
    compare = subprocess.run(
        _rapt_plan() + ["compare", str(PLAN), str(log), "--out", str(out), "--dithers", "0", "--bootstrap", "0"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert compare.returncode == 0, compare.stderr + compare.stdout
    assert (out / "comparison.json").exists() and sid in compare.stdout


def _obstacle_scenario():
    """imitation7 scenario whose route passes 10 m from an obstacle the sonar must find (batch: no collision)."""
    mission = load_mission(ROOT / "examples" / "imitation7.toml")
    u = np.random.default_rng(1).random((400, mission.dim))[231]
    return mission, u


@pytest.mark.slow  # 450 s of mission on a bare autopilot: about 20 s
def test_a_virtual_obstacle_is_seen_and_avoided_on_a_vehicle_without_sonar():
    mission, u = _obstacle_scenario()
    flight = Flight(mission, u, "obstacle", str(ROOT / "examples" / "imitation7.toml"))
    with bare_vehicle(mission, u) as (connection, fs):
        result = run_vehicle(
            flight, connection, timeout_s=450 / SPEEDUP, guard=None
        )  # past all three obstacles by 330 s
    assert fs.stats.setpoints > 0 and result.ended.startswith("wall-time limit") and not result.watchdog
    scen = make_scenarios(mission, u[None, :])
    x, y = result.track[:, 1], result.track[:, 2]
    d = polygon_signed_distance(x, y, np.repeat(scen.obstacles, len(x), axis=0))[0]
    closest = d.min(axis=0)
    assert closest.min() > 0  # never touched one
    assert closest.min() < 30  # but passed close: it was in the way and the vehicle went round it
    assert result.decisions["missed"] == 0
    # what the back-seat went round came from the virtual sonar, in the vehicle's own sensor stream
    assert result.virtual["contacts_sent"] > 0 and result.virtual["gauge_sent"] > 0


def test_the_scenarios_battery_running_empty_ends_the_run_as_its_own_outcome():
    """The virtual gauge reaching empty breaks the watchdog's battery rule at once; the referee's next row
    calls it the scenario's own end, "battery empty", the outcome the plan's batch model predicts (not a
    watchdog take-over, which ``rapt-plan compare`` could not score)."""
    from sim.uuv.missionfile import load_mission_text
    from sim.uuv.scoring import mode_name

    path = ROOT / "examples" / "range2017.toml"
    mission = load_mission_text(path.read_text().replace("battery_wh = 1400.0", "battery_wh = 100.0"), str(path))
    u = flight_from_plan(PLAN, "pair1a").u.copy()
    u[-1] = 0.0  # the lowest starting charge: 5 Wh, empty about 96 s in
    batch = sim.uuv.simulate(mission, u[None, :], trajectories=True)
    with bare_vehicle(mission, u) as (connection, _):
        result = run_vehicle(Flight(mission, u, "empty", str(path)), connection, timeout_s=60, guard=None)
    assert result.ended == "battery empty", result.ended  # whether or not the watchdog saw it first
    assert abs(result.sim_s - batch.trajectory(0)[-1, 0]) <= 2 * mission.dt
    assert mode_name(result.scores) == batch.mode_names[batch.modes[0]] == "TF"
    assert result.timeline[-1].name == "recover" and result.timeline[-1].detail == "surfaced and disarmed"


def test_ctrl_c_surfaces_and_disarms_the_vehicle():
    flight = flight_from_plan(PLAN, "pair2b")

    def operator(step):
        if step.name == "clock":
            raise KeyboardInterrupt

    with bare_vehicle(flight.mission, flight.u) as (connection, fs):
        with pytest.raises(KeyboardInterrupt):
            run_vehicle(flight, connection, say=operator, guard=None)
        truth = fs.bare.truth()
        # SURFACE, then disarmed; at the surface ArduSub's SURFACE hands over to ALT_HOLD by itself
        assert fs.mode in (9, 2) and not fs.armed
        assert truth.depth < 0.3
