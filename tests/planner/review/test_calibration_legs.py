"""A thruster vehicle's calibration run, flown by the batch world, calibrates it alone; legs cut short are refused.

The vehicle is not the file's and not a torpedo: its draw rises linearly with speed (power
exponent 1), it is slower and saturates (speed gain 0.8, at most 1.2 m/s), turns faster
and takes 6-7 s to surface, where it makes at most 0.45 m/s and draws 70 W more.  Its speed
loop flies an earth-frame velocity (as ArduSub's GUIDED does), 30 % of a change coming with an
8 s time constant.  A small scripted autonomy flies the legs a calibration run
would (a hold, straight legs at four commanded speeds, the last above saturation, a turn
at the rate limit after each, both ways, an ascent that goes on at the surface, and a dive) and the log lists them in its record.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

import planner.review.calibrate as calibration
import sim.uuv
from planner.review.calibrate import calibrate
from planner.review.calibration_legs import cut_legs, is_calibration_log
from planner.review.calibration_terms import is_water, knot_command, knot_name, term_need
from planner.review.segment_fit import TURN_TERMS
from planner.review.vehicle_fit import FITTED, SLOW_TERMS, fit_vehicle
from rapt.errors import InputError
from sim.uuv.bias import Bias
from sim.uuv.scenario import make_scenarios
from sim.uuv.world import World
from tests.support.simlogs import SimRun

MISSION = Path(__file__).resolve().parents[3] / "examples" / "range2017.toml"
#: The mission file's vehicle block: a thruster vehicle's datasheet, 20-50 % off.
FILE_BLOCK = {
    "cruise_speed": 1.0,
    "max_speed": 1.5,
    "speed_gain": 1.0,
    "surge_time_constant_s": 3.0,
    "max_turn_rate_dps": 15.0,
    "yaw_time_constant_s": 2.0,
    "heading_time_s": 3.0,
    "hotel_w": 90.0,
    "drag_w": 180.0,
}
#: The vehicle that flies.
TRUE_BLOCK = {
    **FILE_BLOCK,
    "max_speed": 1.2,
    "speed_gain": 0.8,
    "surge_time_constant_s": 2.2,
    "max_turn_rate_dps": 20.0,
    "yaw_time_constant_s": 1.5,
    "heading_time_s": 2.0,
    "hotel_w": 120.0,
    "drag_w": 250.0,
    "power_exponent": 1.0,
    "ascent_rate_mps": 0.3,
    "surface_max_speed": 0.45,
    "surface_power_w": 70.0,
    "slow_share": 0.3,
    "slow_time_constant_s": 8.0,
}
#: The flown vehicle's speed loop (the file's is a torpedo's "surge" loop).
TRUE_CONTROL = "vector"
#: (kind, name, start s, end s, commanded speed, turn: +1 right / -1 left / 0 straight, surface)
LEGS = [
    ("hold", "hold", 0, 120, 0.0, 0, False),
    ("straight", "speed-0.5", 120, 210, 0.5, 0, False),
    ("turn", "turn-right-0.5", 210, 230, 0.5, 1, False),
    ("straight", "speed-0.9", 230, 340, 0.9, 0, False),
    ("turn", "turn-left-0.9", 340, 360, 0.9, -1, False),
    ("straight", "speed-1.3", 360, 460, 1.3, 0, False),
    ("turn", "turn-right-1.3", 460, 480, 1.3, 1, False),
    ("straight", "speed-1.8", 480, 600, 1.8, 0, False),
    ("turn", "turn-left-1.8", 600, 620, 1.8, -1, False),
    ("ascent", "ascent", 620, 690, 1.0, 0, True),
    ("dive", "dive", 690, 720, 0.0, 0, False),
]


def mission_text(block: dict) -> str:
    text = MISSION.read_text(encoding="utf-8")
    lines = text.splitlines()
    start = lines.index("[vehicle]")
    end = next(i for i in range(start + 1, len(lines)) if lines[i].startswith("["))
    kept = [ln for ln in lines[start + 1 : end] if "=" not in ln or ln.split("=")[0].strip() not in block]
    body = [f"{k} = {v!r}" if isinstance(v, str) else f"{k} = {float(v)!r}" for k, v in block.items()]
    return "\n".join(lines[: start + 1] + body + kept + lines[end:]) + "\n"


def thruster_missions(d: Path) -> tuple:
    """The file's mission (path and loaded) and the true one, written in ``d``."""
    (d / "file.toml").write_text(mission_text(FILE_BLOCK))
    (d / "true.toml").write_text(mission_text({**TRUE_BLOCK, "velocity_control": TRUE_CONTROL}))
    return d / "file.toml", sim.uuv.load_mission(d / "file.toml"), sim.uuv.load_mission(d / "true.toml")


@pytest.fixture(scope="module")
def missions(tmp_path_factory):
    return thruster_missions(tmp_path_factory.mktemp("thruster"))


def fly_legs(mission, truth, water: Bias | None = None) -> tuple[SimRun, float, np.ndarray]:
    """The legs flown by ``truth`` in the batch world (lock-step, as SIL logs it) in ``water`` (default:
    the tide table's): a run, its start time, its row."""
    u = np.full(mission.dim, 0.5)
    scen = make_scenarios(mission, u[None, :])
    assert scen.valid[0]
    world = World(scen, plant=truth, bias=water)
    one = np.ones(1, dtype=bool)
    dt = mission.dt
    steps, sps = [], []
    heading_cmd = float(world.state.heading[0])
    last = None
    for k in range(int(LEGS[-1][3] / dt) + 1):
        t = k * dt
        tel = world.telemetry(t)
        s = world.state
        steps.append(
            [t, tel.x[0], tel.y[0], tel.heading[0], tel.energy_hj[0], tel.surfaced[0], s.surge[0], s.yaw_rate[0]]
        )
        leg = next((lg for lg in LEGS if lg[2] <= t < lg[3]), None)
        if leg is None:
            sps.append([np.nan, np.nan, np.nan])
            continue
        _, _, _, _, speed, turn, surface = leg
        if turn and leg is not last:  # a heading step: turned at the rate limit, then closed by the heading loop
            heading_cmd = float(tel.heading[0]) + turn * 2.5
        last = leg
        sps.append([heading_cmd, speed, float(surface)])
        world.advance(t, np.array([heading_cmd]), np.array([speed]), np.array([surface]), one)
    legs = [{"kind": k, "name": n, "start_s": float(a), "end_s": float(b), "speed": v} for k, n, a, b, v, _, _ in LEGS]
    meta = {"mission": mission.name, "u": u.tolist(), "scenario_id": "calibration", "legs": legs}
    run = SimRun(np.array(steps, dtype=float), np.array(sps, dtype=float), meta, path=Path("calibration.mcap"))
    run.events, run.ended, run.complete_file = [], "", True  # type: ignore[attr-defined]
    return run, float(scen.start_time[0]), u


@pytest.fixture(scope="module")
def flown(missions):
    _, file_mission, true_mission = missions
    return fly_legs(file_mission, true_mission.vehicle)


@pytest.fixture(scope="module")
def fitted(missions, flown):
    _, file_mission, _ = missions
    run, start, _ = flown
    return fit_vehicle(file_mission, [run], [start], bootstrap=0)


def test_the_log_is_a_calibration_run_with_legs_flown_to_their_end(missions, flown):
    _, mission, _ = missions
    run, _, _ = flown
    assert is_calibration_log(run)
    assert cut_legs([run], ["calibration.mcap"], mission.dt) == []
    # the vehicle saturates: the fastest leg's surge is max_speed, not 0.8 x 1.8
    fast = (run.steps[:, 0] > 560) & (run.steps[:, 0] < 600)
    assert run.steps[fast, 6] == pytest.approx(TRUE_BLOCK["max_speed"], abs=0.01)


def truth_of(name: str) -> float:
    """The flown vehicle's value of a fitted term: a field, its settled speed at a knot's command, or the water."""
    cmd = knot_command(name)
    if cmd is not None:
        return min(TRUE_BLOCK["speed_gain"] * cmd, TRUE_BLOCK["max_speed"])
    if is_water(name):
        return 1.0 if name.endswith("scale") else 0.0  # the batch world flew the tide table's current
    return TRUE_BLOCK[name]


def test_one_calibration_log_identifies_every_parameter_of_a_thruster_vehicle(fitted):
    est = fitted.estimate
    # the measured speed curve replaces speed_gain and max_speed, one knot per commanded speed, and the
    # current the run flew in is fitted beside the vehicle
    knots = {knot_name(v) for kind, *_, v, _, _ in LEGS if kind == "straight"}
    assert set(est.names) == (set(FITTED) - {"speed_gain", "max_speed"}) | knots | {
        "water.current_scale",
        "water.current_cross",
    }
    # its speed loop flies an earth-frame velocity with a slow part: the fit says so
    assert fitted.vehicle.velocity_control == "vector" and fitted.control["file"] == "surge"
    rms = fitted.control["position_rms_m"]
    assert rms["vector"] < 0.2 * rms["surge"]
    for n in est.names:
        truth, got, se = truth_of(n), fitted.value(n), fitted.stderr[n]
        assert est.identified[n], (n, est.stderr[n], fitted.unidentified)
        # identified: posterior s.d. below half the prior's
        prior = next(p for p in est.priors if p.name == n)
        assert est.stderr[n] < 0.5 * prior.sd, n
        # within its standard errors, plus 0.2 % (the turn terms are noise-free here, and a settled speed is
        # measured a few mm/s short of where a first-order lag ends, which the water fitted beside it
        # shares), or 8 % for the slow part (warmed over the minute of set-points before each segment:
        # the run's first segment has none)
        floor = 0.08 if n in SLOW_TERMS else 2e-3
        assert abs(got - truth) < 3 * se + floor * truth, (n, got, truth, se)
        assert got == pytest.approx(truth, rel=0.1, abs=0.01), n
    assert fitted.unidentified == {}
    assert fitted.rms_after["energy_wh"] < 0.1 * fitted.rms_before["energy_wh"]


@pytest.mark.slow
def test_a_cubic_model_cannot_fit_the_thruster_draw(missions, flown, fitted):
    """Fixed at the torpedo's exponent, the energy residual stays far above the log's hectojoule steps."""
    _, mission, _ = missions
    run, start, _ = flown
    cubic = fit_vehicle(mission, [run], [start], fit=[n for n in FITTED if n != "power_exponent"], bootstrap=0)
    assert cubic.rms_after["energy_wh"] > 5 * fitted.rms_after["energy_wh"]


@pytest.mark.slow
def test_the_water_the_run_flew_in_is_fitted_beside_the_vehicle_and_written(missions, tmp_path, monkeypatch):
    """A vehicle in slack water where the tide table says 1 m/s (as on the firmware): the run's legs
    tell the current from the vehicle, so the speeds come out right and the file gets the water."""
    file_path, file_mission, true_mission = missions
    run, start, _ = fly_legs(file_mission, true_mission.vehicle, Bias(current_scale=0.0))
    log = fake_log(tmp_path, monkeypatch, run)
    out = tmp_path / "slack.toml"
    result = calibrate(file_path, [log], out, bootstrap=0)
    assert result.estimate.identified["water.current_scale"]
    assert abs(result.value("water.current_scale")) < 3 * result.stderr["water.current_scale"] + 0.02
    for cmd in (0.9, 1.3, 1.8):
        assert result.value(knot_name(cmd)) == pytest.approx(truth_of(knot_name(cmd)), abs=0.02)
    cal = sim.uuv.load_mission(out)
    assert cal.execution_bias.current_scale == pytest.approx(0.0, abs=0.05)
    assert "calibration run calibration.mcap" in (cal.execution_bias_source or "")
    # the same legs fitted in the table's water (no water term: not read as a calibration run) fit worse
    naive_run = dataclasses.replace(run, meta={**run.meta, "legs": []})
    naive = fit_vehicle(
        file_mission, [naive_run], [start], fit=[n for n in FITTED if n != "ascent_rate_mps"], bootstrap=0
    )
    assert naive.rms_after["position_m"] > 3 * result.rms_after["position_m"]


def test_a_steady_current_across_the_flood_is_fitted_and_written(missions, tmp_path, monkeypatch):
    """A steady current no scale of the tide table gives (SITL's: 0.3 m/s setting across the table's
    flood, the table's own tide absent): the legs' sideways drift measures it, the speeds stay right."""
    file_path, file_mission, true_mission = missions
    run, start, _ = fly_legs(file_mission, true_mission.vehicle, Bias(current_scale=0.0, current_cross=0.3))
    out = tmp_path / "cross.toml"
    result = calibrate(file_path, [fake_log(tmp_path, monkeypatch, run)], out, bootstrap=0)
    assert result.estimate.identified["water.current_cross"]
    assert result.value("water.current_cross") == pytest.approx(0.3, abs=0.02)
    assert abs(result.value("water.current_scale")) < 0.05
    for cmd in (0.9, 1.3, 1.8):
        assert result.value(knot_name(cmd)) == pytest.approx(truth_of(knot_name(cmd)), abs=0.02)
    cal = sim.uuv.load_mission(out)
    assert cal.execution_bias.current_cross == pytest.approx(0.3, abs=0.02)
    # flown in the calibrated file's water, the planner's world drifts as the vehicle did
    assert result.rms_after["position_m"] < 0.2 * result.rms_before["position_m"]


def test_a_recalibration_with_the_days_water_keeps_the_loop_the_compared_calibration_chose(
    missions, flown, fitted, tmp_path, monkeypatch
):
    """``calibrate --bias``: the comparison predicted with a calibrated vehicle whose loop and turn the
    calibration run found; adding the day's water keeps that loop instead of fitting both again, and fits
    the turn from where it was found (the noon step's time)."""
    file_path, _, _ = missions
    run, _, _ = flown
    cmp = tmp_path / "comparison.json"
    cmp.write_text(
        json.dumps(
            {
                "schema": "rapt.comparison/2",
                "plan": {"id": "p1", "mission": "range2017"},
                "bias": {"current_scale": {"estimate": 1.0, "stderr": 0.01, "identified": True}},
                "correction": {"used": True},
                "calibrated_vehicle": {"velocity_control": "vector", **{n: fitted.value(n) for n in TURN_TERMS}},
            }
        )
    )
    result = calibrate(file_path, [fake_log(tmp_path, monkeypatch, run)], tmp_path / "day.toml", bias=cmp, bootstrap=0)
    assert result.vehicle.velocity_control == "vector" and "kept" in result.control
    assert "position_rms_m" not in result.control  # the surge loop was not fitted
    for n in fitted.estimate.names:
        if n in result.estimate.names and knot_command(n) is not None:
            assert result.value(n) == pytest.approx(fitted.value(n), abs=0.02), n
    assert result.rms_after["position_m"] < 1.5 * fitted.rms_after["position_m"] + 0.05
    for n in TURN_TERMS:
        assert result.estimate.identified[n] and result.value(n) == pytest.approx(truth_of(n), rel=0.05), n
    assert "chosen by the calibration compared" in (tmp_path / "day.toml").read_text()


# -- the command: one log is enough; legs cut short write nothing ---------------------------------
def fake_log(tmp_path, monkeypatch, run) -> Path:
    p = tmp_path / "calibration.mcap"
    p.write_bytes(b"calibration run log")
    monkeypatch.setattr(calibration, "read_run", lambda path: run)
    return p


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.mark.slow  # a whole calibration, about 14 s
def test_calibrate_accepts_the_calibration_log_alone(missions, flown, tmp_path, monkeypatch):
    file_path, _, _ = missions
    run, _, _ = flown
    log = fake_log(tmp_path, monkeypatch, run)
    before = (_digest(file_path), _digest(log))
    out = tmp_path / "cal.toml"
    result = calibrate(file_path, [log], out, bootstrap=0)
    assert (_digest(file_path), _digest(log)) == before
    assert result.runs == 1 and result.unidentified == {}
    cal = sim.uuv.load_mission(out)
    assert cal.vehicle.power_exponent == pytest.approx(1.0, rel=0.1)
    assert cal.vehicle.ascent_rate_mps == pytest.approx(0.3, rel=0.1)
    side = json.loads(out.with_suffix(".json").read_text())
    assert side["unidentified"] == {} and side["cut_short_legs"] == [] and side["ascents_timed"] == 1


def cut_run(run, at_s: float, events: list) -> object:
    keep = run.steps[:, 0] <= at_s
    sp = run.setpoints[keep].copy()
    sp[-1] = np.nan
    out = dataclasses.replace(run, steps=run.steps[keep], setpoints=sp)
    out.events, out.ended, out.complete_file = events, "", True  # type: ignore[attr-defined]
    return out


@pytest.mark.slow
def test_legs_cut_short_by_the_watchdog_write_nothing_and_say_which(missions, flown, tmp_path, monkeypatch):
    file_path, _, _ = missions
    run, _, _ = flown
    cut = cut_run(run, 480.0, [{"source": "watchdog", "event": "intervention", "reason": "operational_area"}])
    log = fake_log(tmp_path, monkeypatch, cut)
    out = tmp_path / "cal.toml"
    with pytest.raises(InputError) as e:
        calibrate(file_path, [log], out, bootstrap=0)
    msg = str(e.value)
    assert "\n" not in msg and "--keep-unidentified" in msg and "nothing written" in msg
    # the curve's fastest knot (its leg was cut) and the ascent
    assert "speed_curve[1.8]" in msg and "ascent_rate_mps" in msg and "the watchdog took over: operational_area" in msg
    assert "'speed-1.8'" in msg and "'ascent'" in msg
    assert not out.exists() and not out.with_suffix(".json").exists()
    # told to keep them: written, those at the file's values, and the header and sidecar say which and why
    result = calibrate(file_path, [log], out, bootstrap=0, keep_unidentified=True)
    kept = result.unidentified
    assert {"speed_curve[1.8]", "ascent_rate_mps"} <= set(kept)
    need = term_need("speed_curve[1.8]")[0]
    assert kept["speed_curve[1.8]"].startswith(need) and "cut short" in kept["speed_curve[1.8]"]
    cal = sim.uuv.load_mission(out)
    # the knot keeps the file's vehicle's speed at 1.8 m/s (speed_gain 1, at most max_speed), the ascent its 0
    assert cal.vehicle.speed_curve[-1] == (1.8, FILE_BLOCK["max_speed"]) and cal.vehicle.ascent_rate_mps == 0.0
    assert [c for c, _ in cal.vehicle.speed_curve] == [0.5, 0.9, 1.3, 1.8]
    text = out.read_text()
    assert f"#   to identify speed_curve[1.8]: {need}" in text and "watchdog took over" in text
    side = json.loads(out.with_suffix(".json").read_text())
    assert {c["name"] for c in side["cut_short_legs"]} >= {"speed-1.8", "ascent", "dive"}


@pytest.mark.slow  # a whole calibration, about 15 s
def test_a_log_that_ends_early_names_the_end_and_complete_legs_are_not_refused(missions, flown, tmp_path, monkeypatch):
    file_path, _, _ = missions
    run, _, _ = flown
    # only the dive (which identifies nothing) is missing: every parameter is identified, so it is written
    log = fake_log(tmp_path, monkeypatch, cut_run(run, 700.0, []))
    result = calibrate(file_path, [log], tmp_path / "ok.toml", bootstrap=0)
    assert [c.name for c in result.cut] == ["dive"] and "the log ended" in result.cut[0].reason
    assert result.unidentified == {}


#: The same thruster vehicle turning otherwise than its file says: slower and lagging more; faster and lagging
#: less. Fitted to the headings alone, the second's log holds two optima: from where the loop's fit ends the
#: turn fit lands on one where the turn rate and the lags trade off (28.9 deg/s, 0.54 s, 1.04 s: a 0.76 deg
#: residual), from the file's values on the vehicle's own.
TURNS = {
    "slower": {"max_turn_rate_dps": 9.0, "yaw_time_constant_s": 3.0, "heading_time_s": 4.5},
    "faster": {"max_turn_rate_dps": 30.0, "yaw_time_constant_s": 0.8, "heading_time_s": 0.9},
}


@pytest.mark.slow  # two calibrations of a turning vehicle, about 15 s each
@pytest.mark.parametrize("turns", list(TURNS))
def test_a_vehicle_that_turns_otherwise_than_its_file_has_its_turn_identified(tmp_path, turns):
    block = {**TRUE_BLOCK, **TURNS[turns]}
    (tmp_path / "file.toml").write_text(mission_text(FILE_BLOCK))
    (tmp_path / "true.toml").write_text(mission_text({**block, "velocity_control": TRUE_CONTROL}))
    file_mission, truth = sim.uuv.load_mission(tmp_path / "file.toml"), sim.uuv.load_mission(tmp_path / "true.toml")
    run, start, _ = fly_legs(file_mission, truth.vehicle)
    fitted = fit_vehicle(file_mission, [run], [start], bootstrap=0)
    assert fitted.vehicle.velocity_control == "vector"
    for n in TURNS[turns]:
        assert fitted.estimate.identified[n], (n, fitted.unidentified)
        assert fitted.value(n) == pytest.approx(block[n], rel=0.05), n
    assert fitted.rms_after["heading_deg"] <= 0.1 * fitted.rms_before["heading_deg"]
