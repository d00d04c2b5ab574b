"""The vehicle calibration on runs from the batch simulator (bit-exact with lock-step SIL logs).

The logs are flown by the true range2017 vehicle; the calibration starts from a copy of the
mission whose [vehicle] block is deliberately wrong and must recover the true values.
tests/cli/test_calibrate.py does the same on real SIL logs through the command line.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

import planner.review.calibrate as calibration
import sim.uuv
from planner.review.calibrate import calibrate, calibrated_text
from planner.review.logs import LogError
from planner.review.segments import MAX_SETPOINT_DELAY_S, replay, segment_batch
from planner.review.vehicle_fit import FITTED, MIN_LOGS, SLOW_TERMS, fit_vehicle
from rapt.errors import InputError
from sim.uuv.environment import tidal_current
from sim.uuv.scenario import make_scenarios
from sim.uuv.vehicle import VehicleState, step_vehicle
from tests.support.simlogs import sim_runs

ROOT = Path(__file__).resolve().parents[3]
MISSION = ROOT / "examples" / "range2017.toml"
#: Fields plan runs of the batch simulator cannot identify: no command asks for more than the vehicle
#: reaches (max_speed), and their logs carry no surface command to time an ascent by.
UNSEEN = ("max_speed", "ascent_rate_mps", "surface_max_speed")
#: Fitted but true at 0, so checked in W rather than as a share: the draw added at the surface.
AT_ZERO = ("surface_power_w",)
#: The deliberately wrong block: every fitted field but max_speed and the ascent rate 20-40 % off.
WRONG = {
    "speed_gain": 1.25,
    "surge_time_constant_s": 5.5,
    "max_turn_rate_dps": 9.0,
    "yaw_time_constant_s": 4.0,
    "heading_time_s": 5.0,
    "hotel_w": 52.0,
    "drag_w": 115.0,
    "power_exponent": 2.2,
}


def wrong_mission_text() -> str:
    """range2017.toml with WRONG in its [vehicle] block: set lines keep their place (and get a comment)."""
    lines = MISSION.read_text().splitlines()
    start = lines.index("[vehicle]")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    present = {ln.split("=")[0].strip() for ln in lines[start + 1 : end] if "=" in ln}
    block = [f"{k} = {v!r}" for k, v in WRONG.items() if k not in present]
    for ln in lines[start + 1 : end]:
        key = ln.split("=")[0].strip()
        block.append(f"{key} = {WRONG[key]!r}  # wrong on purpose" if key in WRONG else ln)
    return "\n".join(lines[: start + 1] + block + lines[end:]) + "\n"


@pytest.fixture(scope="module")
def true_mission():
    return sim.uuv.load_mission(MISSION)


@pytest.fixture(scope="module")
def wrong(tmp_path_factory):
    path = tmp_path_factory.mktemp("wrong") / "wrong.toml"
    path.write_text(wrong_mission_text())
    return path


@pytest.fixture(scope="module")
def flown(true_mission):
    X = np.random.default_rng(3).random((8, true_mission.dim))
    U = X[make_scenarios(true_mission, X).valid][:3]
    return U, sim_runs(true_mission, U), list(make_scenarios(true_mission, U).start_time)


@pytest.fixture(scope="module")
def fitted(wrong, flown):
    U, runs, starts = flown
    return fit_vehicle(sim.uuv.load_mission(wrong), runs, starts, bootstrap=0)


def test_the_wrong_file_is_what_the_test_says(wrong, true_mission):
    v = sim.uuv.load_mission(wrong).vehicle
    for k, value in WRONG.items():
        assert getattr(v, k) == value
        assert 0.2 <= abs(value / getattr(true_mission.vehicle, k) - 1) <= 0.4
    assert v.max_speed == true_mission.vehicle.max_speed


@pytest.mark.slow  # the module's fit of three runs, about 22 s
def test_the_fit_recovers_the_true_block_within_10_percent(fitted, true_mission):
    est = fitted.estimate
    # a torpedo's speed loop drives its surge: the simpler loop stands, and its slow part is not fitted
    assert fitted.vehicle.velocity_control == "surge" and fitted.control["chosen"] == "surge"
    rms = fitted.control["position_rms_m"]
    assert rms["surge"] < 0.5 * rms["vector"] and rms["surge"] < 0.2 * fitted.rms_before["position_m"]
    assert not set(SLOW_TERMS) & set(est.names)
    for n in FITTED:
        if n in UNSEEN or n in AT_ZERO or n in SLOW_TERMS:
            continue
        assert est.identified[n], n
        assert getattr(fitted.vehicle, n) == pytest.approx(getattr(true_mission.vehicle, n), rel=0.1), n
        assert 0 < est.stderr[n] < 0.05 * getattr(true_mission.vehicle, n), n
    # the simulated vehicle draws nothing more at the surface and goes as fast there as below
    for n in AT_ZERO:
        assert est.identified[n] and abs(getattr(fitted.vehicle, n)) < 5.0, (n, getattr(fitted.vehicle, n))
    # no command asked for more than the vehicle reaches: max_speed is not identified and keeps the file's value
    for n in UNSEEN:
        assert not est.identified[n], n
        assert getattr(fitted.vehicle, n) == getattr(fitted.original, n), n
    assert fitted.rms_after["position_m"] < 0.01 * fitted.rms_before["position_m"]
    assert fitted.rms_after["energy_wh"] < 0.05  # the log's whole-hectojoule steps
    # nothing but the fitted fields changes
    rest = [f.name for f in dataclasses.fields(fitted.vehicle) if f.name not in FITTED]
    assert all(getattr(fitted.vehicle, n) == getattr(fitted.original, n) for n in rest)


@pytest.mark.slow  # the module's fit of three runs, about 22 s
def test_the_calibrated_file_loads_changes_only_vehicle_values_and_predicts_the_true_runs(
    fitted, wrong, flown, true_mission, tmp_path
):
    text = wrong.read_text()
    out = calibrated_text(text, fitted)
    assert out == calibrated_text(text, fitted)  # deterministic
    p = tmp_path / "calibrated.toml"
    p.write_text(out)
    cal = sim.uuv.load_mission(p)
    original = sim.uuv.load_mission(wrong)
    for n in FITTED:
        assert getattr(cal.vehicle, n) == pytest.approx(getattr(fitted.vehicle, n), rel=1e-4)
    assert dataclasses.replace(cal, vehicle=original.vehicle) == original  # the rest of the mission is the file's
    # only [vehicle] lines and the leading comment block differ; comments on changed lines are kept
    body = out.split("# Everything below is the input mission file; only those [vehicle] values changed.\n\n", 1)[1]
    changed = [(a, b) for a, b in zip(text.splitlines(), body.splitlines()) if a != b]
    assert changed and all(a.split("=")[0] == b.split("=")[0] for a, b in changed)
    assert all(b.endswith("# wrong on purpose") for a, b in changed if "wrong on purpose" in a)
    assert tomllib.loads(body)["vehicle"]["max_speed"] == tomllib.loads(text)["vehicle"]["max_speed"]
    U, _, _ = flown
    truth = sim.uuv.simulate(true_mission, U)
    np.testing.assert_array_equal(sim.uuv.simulate(cal, U).modes, truth.modes)
    # the plan's autonomy on the calibrated vehicle: the plant override
    np.testing.assert_array_equal(sim.uuv.simulate(true_mission, U, plant=cal.vehicle).modes, truth.modes)


def test_segments_rebuild_the_start_surge_from_positions(true_mission, flown):
    """The logged speed column is ground speed on a real vehicle: the replay must not depend on it."""
    U, runs, starts = flown
    seg = segment_batch(true_mission, runs, starts)
    px, py, _, _ = replay(true_mission, seg)
    ground = [dataclasses.replace(r, steps=r.steps.copy()) for r in runs]
    for r in ground:
        r.steps[:, 6] = np.hypot(*np.gradient(r.steps[:, 1:3], axis=0).T) / true_mission.dt  # ground speed
    seg_g = segment_batch(true_mission, ground, starts)
    gx, gy, _, _ = replay(true_mission, seg_g)
    first = seg.t[:, 0] == 0.0  # a run's first segment: no step before it, the logged column is used
    v = seg.valid & ~first[:, None]
    assert np.abs(gx - px)[v].max() < 1e-3 and np.abs(gy - py)[v].max() < 1e-3
    assert np.abs(px - seg.obs_x)[seg.valid].max() < 1e-3


# -- the command's function: inputs, errors, outputs ---------------------------------------------
@pytest.fixture
def fake_logs(tmp_path, flown, true_mission, monkeypatch):
    """Log files whose reading gives the simulated runs (what a lock-step SIL log of them holds)."""
    U, runs, _ = flown
    by_path = {}
    paths = []
    for i, (u, r) in enumerate(zip(U, runs)):
        p = tmp_path / f"run{i}.mcap"
        p.write_bytes(f"log {i}".encode())
        by_path[p.resolve()] = dataclasses.replace(
            r, meta={"mission": true_mission.name, "u": u.tolist(), "scenario_id": f"s{i}"}
        )
        paths.append(p)
    monkeypatch.setattr(calibration, "read_run", lambda p: by_path[Path(p).resolve()])
    return paths, by_path


def _digests(paths) -> dict:
    return {str(p): hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths}


@pytest.mark.slow
def test_calibrate_writes_the_file_and_sidecar_and_modifies_no_input(fake_logs, wrong, tmp_path, true_mission):
    paths, _ = fake_logs
    paths = paths[:MIN_LOGS]
    before = _digests([wrong, *paths])
    out = tmp_path / "out" / "calibrated.toml"
    result = calibrate(wrong, paths, out, bootstrap=0)
    assert _digests([wrong, *paths]) == before
    cal = sim.uuv.load_mission(out)
    assert cal.vehicle.drag_w == pytest.approx(true_mission.vehicle.drag_w, rel=0.1)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["schema"] == "rapt.calibration/1" and set(side["parameters"]) == set(FITTED) - set(SLOW_TERMS)
    assert side["velocity_control"]["value"] == "surge"  # a torpedo: no slow vector loop to fit
    assert side["parameters"]["max_speed"]["identified"] is False
    assert side["residual_rms"]["after"]["position_m"] < side["residual_rms"]["before"]["position_m"]
    assert [lg["name"] for lg in side["logs"]] == [p.name for p in paths]
    text = out.read_text()
    assert text.startswith(f"# Calibrated by rapt-plan calibrate from {MIN_LOGS} run log(s):")
    assert "max_speed" in text and "kept: not identified" in text
    # deterministic: the same inputs write the same bytes
    again = tmp_path / "again.toml"
    calibrate(wrong, paths, again, bootstrap=0)
    assert again.read_bytes() == out.read_bytes()
    assert again.with_suffix(".json").read_bytes() == out.with_suffix(".json").read_bytes()
    assert result.runs == MIN_LOGS


def _one_line(exc: BaseException, expect: str) -> None:
    msg = str(exc)
    assert "\n" not in msg and expect in msg, msg


def test_too_few_logs_a_repeated_log_and_an_out_over_an_input_are_refused_before_reading(fake_logs, wrong, tmp_path):
    paths, _ = fake_logs
    with pytest.raises(InputError) as e:
        calibrate(wrong, paths[: MIN_LOGS - 1], tmp_path / "c.toml")
    _one_line(e.value, f"at least {MIN_LOGS} runs")
    with pytest.raises(InputError) as e:
        calibrate(wrong, [paths[0], paths[0]], tmp_path / "c.toml")
    _one_line(e.value, "given twice")
    with pytest.raises(InputError) as e:
        calibrate(wrong, paths, wrong)
    _one_line(e.value, "would overwrite an input")
    with pytest.raises(InputError) as e:
        calibrate(wrong, paths, tmp_path / "c.yaml")
    _one_line(e.value, "is not a .toml file")
    assert not (tmp_path / "c.toml").exists() and not (tmp_path / "c.json").exists()


def test_logs_of_another_mission_or_without_flight_are_refused_naming_the_log(fake_logs, wrong, tmp_path):
    paths, by_path = fake_logs
    run = by_path[paths[1].resolve()]
    by_path[paths[1].resolve()] = dataclasses.replace(run, meta={**run.meta, "mission": "uuv18"})
    with pytest.raises(LogError) as e:
        calibrate(wrong, paths, tmp_path / "c.toml")
    _one_line(e.value, f"LOG: {paths[1].name} was flown on mission 'uuv18', but wrong.toml is mission 'range2017'")
    by_path[paths[1].resolve()] = dataclasses.replace(run, setpoints=np.full_like(run.setpoints, np.nan))
    with pytest.raises(LogError) as e:
        calibrate(wrong, paths, tmp_path / "c.toml")
    _one_line(e.value, f"LOG: {paths[1].name} has no replayable step")
    assert not (tmp_path / "c.toml").exists()


def test_a_step_whose_set_point_came_late_is_not_replayed(true_mission, flown):
    """A vehicle-paced run flies the previous set-point until the next arrives: such a step is cut out."""
    _, runs, starts = flown
    run = dataclasses.replace(runs[0])
    n = run.steps.shape[0]
    delay = np.zeros(n)
    delay[[10, 11, 200]] = [MAX_SETPOINT_DELAY_S * 2, np.inf, MAX_SETPOINT_DELAY_S]  # late, unanswered, in time
    run.setpoint_delay_s = delay  # type: ignore[attr-defined]
    full = segment_batch(true_mission, runs[:1], starts[:1])
    cut = segment_batch(true_mission, [run], starts[:1])
    assert int(full.valid.sum()) - int(cut.valid.sum()) == 2
    assert not np.isin(cut.t[cut.valid], [run.steps[10, 0], run.steps[11, 0]]).any()


def _continuous_vehicle_runs(mission, runs, starts, vehicle, substep: float = 0.1, steps: int = 900) -> list:
    """What a vehicle-paced log of another, continuously moving vehicle holds: each run's first
    ``steps`` set-points flown in ``substep`` s steps, ground speed in the speed column,
    positions to the centimetre, energy in whole hectojoules."""
    out = []
    for run, t0 in zip(runs, starts):
        s, sp = run.steps[:steps].copy(), run.setpoints[:steps]
        v = VehicleState.at_rest(s[:1, 1], s[:1, 2], s[:1, 3], np.array([1000.0]))
        one = np.ones(1, dtype=bool)
        n_sub = int(round(mission.dt / substep))
        for k in range(s.shape[0] - 1):
            x0, y0 = v.x[0], v.y[0]
            for q in range(n_sub):
                ce, cn = tidal_current(mission.current, t0 + s[k, 0] + q * substep)
                step_vehicle(v, vehicle, sp[k, :1], sp[k, 1:2], ce, cn, substep, one)
            s[k + 1, 1:4] = np.round(v.x[0], 2), np.round(v.y[0], 2), v.heading[0]
            s[k + 1, 4] = np.floor((1000.0 - v.energy_wh[0]) * 36.0)
            s[k + 1, 6] = np.hypot(v.x[0] - x0, v.y[0] - y0) / mission.dt  # ground speed, as GLOBAL_POSITION_INT
            s[k + 1, 7] = v.yaw_rate[0]
        out.append(dataclasses.replace(run, steps=s, setpoints=sp, meta={**run.meta, "pacing": "vehicle"}))
    return out


@pytest.mark.slow
def test_a_continuously_moving_vehicle_of_another_block_is_recovered(true_mission, flown):
    """Not our simulator's 2 s steps: a vehicle flown in 0.1 s steps, logged as a real vehicle logs."""
    _, runs, starts = flown
    other = dataclasses.replace(
        true_mission.vehicle, speed_gain=0.8, max_turn_rate_dps=8.0, yaw_time_constant_s=5.0, hotel_w=60.0, drag_w=220.0
    )
    logged = _continuous_vehicle_runs(true_mission, runs[:2], starts[:2], other)
    cal = fit_vehicle(true_mission, logged, starts[:2], bootstrap=0)
    assert cal.vehicle.velocity_control == "surge"
    for n in FITTED:
        if n in SLOW_TERMS:
            assert n not in cal.estimate.names
            continue
        if n in UNSEEN or n in AT_ZERO:
            assert not cal.estimate.identified[n] or abs(getattr(cal.vehicle, n)) < 5.0, n
            continue
        assert cal.estimate.identified[n], n
        assert getattr(cal.vehicle, n) == pytest.approx(getattr(other, n), rel=0.1), n
        assert abs(getattr(cal.vehicle, n) - getattr(other, n)) < 3 * cal.stderr[n], n  # honest s.e.
    assert cal.model_share > 0
