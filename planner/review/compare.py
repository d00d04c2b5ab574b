"""After the range day: compare run logs with a plan's predictions, estimate the bias, re-plan.

``rapt-plan compare PLAN_DIR LOG.mcap...`` (section 4.6's first lesson: "an automatic way
to identify and apply this bias to our predictions").  :func:`compare`

1. reads every log (:mod:`planner.review.logs`; never modified, damaged ones as far as they go)
   and matches it to its plan scenario by the recorded metadata (:mod:`planner.review.runs`)
   — a log of another mission or plan is refused with a one-line error — and checks each run
   itself (:mod:`planner.review.run_checks`: estimator, position, link, set-point gaps,
   thrusters, depth, pack, gauge, failsafes, uncommanded modes, watchdog); a run whose checks
   fail does not count towards the bias fit unless ``keep_failed``;
2. rebuilds each run's track, scores it with the mission's own scorer and score tree
   (:func:`sim.uuv.replay.score_track`), and sets predicted against observed mode and
   sub-scores per scenario and per pair (did the pair straddle its boundary?), with the
   path error in metres against the predicted trajectory;
3. fits the execution bias (:mod:`sim.uuv.bias`) to all logs jointly (:mod:`planner.review.biasfit`):
   a MAP estimate under documented priors, each parameter with a standard error and whether
   the logs identify it (an unidentified one stays neutral), the runs' observed end
   conditions weighed in by a closed-loop re-simulation;
4. checks the correction before using it (:mod:`planner.review.correction`): leave one log
   out, fit on the others, predict the left-out run's mode and path with and without the fitted
   bias.  The correction is used only when it predicts held-out runs at least as well in
   mode and better in mode or path; otherwise the report says "the logs do not support a
   correction; plan unchanged" and the corrected predictions are the uncorrected ones;
5. re-predicts every run and every plan scenario under the bias used — the corrected
   predictions — and forecasts each as mode probabilities under the execution noise fitted to
   the day's runs (:mod:`planner.review.day_noise`, the plan's assumed noise as its prior),
   alone and with the fitted bias's uncertainty, scoring the day by its Brier score
   (:mod:`planner.review.forecast`); flags the pairs that straddle their boundary with a
   probability below one half under the corrected forecast, with an adjusted "M" scenario
   for each side to move (:mod:`planner.review.replan`); and judges each pair confirmed or
   not by the day's runs, repeats of a scenario included (:mod:`planner.review.confirmations`,
   the rule ``rapt-plan next`` conducts the afternoon by);
6. writes ``comparison.json`` and ``comparison.html`` (:mod:`planner.review.report`), and per
   flown scenario an MCAP for Foxglove overlaying observed, predicted and corrected tracks
   and the runs' checks that warned or failed as Log events (:mod:`planner.review.overlay`).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

import sim.uuv
from planner.common.atomic import write_text_atomic
from planner.common.jsonio import json_value, jsonable
from planner.common.plans import Plan, load_plan
from planner.review.confirmations import RunOutcome, confirmation_table
from planner.review.correction import cross_validate, fit_observed, path_error, rms_path_error
from planner.review.day_noise import fit_day_noise
from planner.review.daybias import day_bias_record
from planner.review.forecast import STRADDLE_BELOW, DayForecast, forecast_day, plan_noise, run_forecast
from planner.review.logs import read_run
from planner.review.replan import adjust_for_bias
from planner.review.run_checks import summary_line, verdict_of
from planner.review.runs import (
    CompareConfig,
    Observation,
    PlanRuns,
    match_logs,
    predict_plan,
    row_index,
    score_observed,
)
from rapt.errors import InputError
from sim.uuv.bias import BIAS_UNITS, NEUTRAL, Bias
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import MODE_NAMES

__all__ = ["compare", "COMPARISON_SCHEMA"]

COMPARISON_SCHEMA = "rapt.comparison/3"
RESULT_NAME = "comparison.json"
#: How the Foxglove overlays' file names begin (:func:`planner.review.overlay.overlay_name`).
OVERLAY_PREFIX = "overlay_"


def _elements(plan: Plan, pair: dict, names: list[str]) -> list[int]:
    """Score columns a pair tests: its elements, and on the root level both root scores (the
    mode), so an adjusted pair tests the same boundary type as planned (TF/SS, not TF/TS)."""
    cols = [names.index(e) for e in pair.get("elements", []) if e in names]
    if not cols or pair.get("level", 0) == 0:
        cols = sorted(set(cols) | {0, 1})
    return cols


def compare(
    plan_path: str | Path,
    log_paths: Sequence[str | Path],
    out_dir: str | Path | None = None,
    cfg: CompareConfig | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Run the comparison (see the module docstring); returns what ``comparison.json`` holds.

    An ``out_dir`` whose ``comparison.json`` would overwrite an input is refused first,
    before any log is read or any run simulated.
    """
    cfg = cfg or CompareConfig()
    say = progress or (lambda _: None)
    if out_dir is not None:
        _check_out_dir(plan_path, log_paths, out_dir)
    plan = load_plan(plan_path)
    m = plan.mission
    if not log_paths:
        raise InputError("LOGS: give at least one .mcap log of a run of this plan")
    say("reading logs")
    runs = [read_run(p) for p in log_paths]
    obs = match_logs(plan, runs)
    ids, U_plan, pred = predict_plan(plan)
    say("scoring logged runs")
    score_observed(m, obs)
    plant = cfg.plant
    calib = None
    if plant is not None:
        say("predicting with the calibrated vehicle")
        calib = sim.uuv.simulate(m, U_plan, trajectories=True, plant=plant)
    baseline = calib if calib is not None else pred
    say("fitting the execution bias")
    counted = _counted(obs, cfg)
    start_times = [float(make_scenarios(m, o.u[None, :]).start_time[0]) for o in counted]
    fit = fit_observed(m, counted, start_times, cfg, cfg.bootstrap)
    say("cross-validating the correction")
    cv = cross_validate(m, counted, start_times, baseline, row_index(ids), cfg)
    bias_used = fit.bias if cv["correction_used"] else Bias()
    say("re-predicting under the fitted bias")
    corr = (
        sim.uuv.simulate(m, U_plan, trajectories=True, bias=bias_used, plant=cfg.plant)
        if cv["correction_used"]
        else baseline
    )
    plan_runs = PlanRuns(ids, U_plan, pred, corr, calib)
    say("fitting the day's execution noise")
    noise = fit_day_noise(plan, counted, plan_runs, plan_noise(plan), cfg.plant)
    say("forecasting under the day's execution noise and the bias's uncertainty")
    fc = forecast_day(plan, obs, plan_runs, fit, cv["correction_used"], cfg, day_noise=noise)
    scen_rows = _scenario_rows(m, obs, plan_runs, fc, counted)
    agreement = _mode_agreement(scen_rows)
    say("re-planning")
    pair_rows, proposals = _pair_rows(plan, obs, plan_runs, bias_used, cfg, fc)
    result = {
        "schema": COMPARISON_SCHEMA,
        "plan": {"id": plan.id, "path": str(plan.path), "mission": m.name, "mission_file": str(plan.mission_file)},
        "logs": _log_rows(obs),
        "run_checks": {
            "keep_failed": cfg.keep_failed,
            "excluded_from_bias_fit": [o.run.path.name for o in obs if not any(o is c for c in counted)],
        },
        "bias": fit.to_dict(),
        "day_bias": day_bias_record(m, fit.bias, bias_used),
        "bias_fit": _biasfit_observed(fit, cfg),
        "calibrated_vehicle": None if plant is None else jsonable(dataclasses.asdict(plant)),
        "cross_validation": cv,
        "correction": {
            "used": cv["correction_used"],
            "bias": bias_used.to_dict(),
            "note": cv["note"],
        },
        "scenarios": scen_rows,
        "mode_agreement": agreement,
        "forecast": fc.summary(scen_rows),
        "pairs": pair_rows,
        "confirmation": day_confirmations(plan, counted, plan_runs),
        "remaining": _remaining(plan, obs, plan_runs),
        "proposals": proposals,
    }
    if out_dir is not None:
        say("writing the report")
        _write(result, plan, obs, plan_runs, Path(out_dir))
    return result


def day_confirmations(plan: Plan, counted: list[Observation], runs: PlanRuns) -> list[dict]:
    """Each pair's confirmation by the day's counted runs, repeats included (:mod:`planner.review.confirmations`)."""
    predicted = {sid: runs.pred.scores[runs.row_of[sid]] for pair in plan.pairs for sid in pair["scenarios"]}
    outcomes = [RunOutcome(o.sid, o.scores if o.mode is not None else None, o.run.path.name) for o in counted]
    return confirmation_table(plan, runs.pred.names, predicted, outcomes)


def _check_out_dir(plan_path: str | Path, log_paths: Sequence[str | Path], out_dir: str | Path) -> None:
    """InputError (one line) when ``out_dir``'s ``comparison.json`` would overwrite a log or the plan.

    Resolves paths only (the plan directory's ``plan.json`` as :func:`planner.common.plans.load_plan`
    finds it), so it runs before any work and creates nothing.
    """
    plan_file = Path(plan_path)
    if plan_file.is_dir():
        plan_file = plan_file / "plan.json"
    inputs = {Path(p).resolve() for p in log_paths} | {plan_file.resolve()}
    if (Path(out_dir) / RESULT_NAME).resolve() in inputs:
        raise InputError(f"--out: {out_dir} would overwrite an input; choose another directory")
    out = Path(out_dir).resolve()
    if any(p.parent == out and p.name.startswith(OVERLAY_PREFIX) for p in inputs):  # planner.review.overlay's names
        raise InputError(f"--out: {out_dir} would overwrite an input (an overlay_*.mcap); choose another directory")


def _log_rows(obs: list[Observation]) -> list[dict]:
    """Per log: its path and scenario, what it holds and lost, and its run checks."""
    return [
        {
            "path": str(o.run.path),
            "scenario": o.sid,
            "messages": o.run.messages,
            "complete": bool(o.run.complete_file and o.run.has_end),
            "lost": o.run.problems,
            "frames_lost": o.run.frames_lost,
            "losses": o.run.losses if o.run.losses is not None else "unknown",
            "checks": o.run.checks,
        }
        for o in obs
    ]


def _counted(obs: list[Observation], cfg: CompareConfig) -> list[Observation]:
    """The runs the bias fit counts: those whose automatic checks did not fail, or all with ``keep_failed``;
    InputError (one line) when that leaves none."""
    counted = [o for o in obs if cfg.keep_failed or verdict_of(o.run.checks) != "fail"]
    if not counted:
        failed = "; ".join(f"{o.run.path.name} ({summary_line(o.run.checks)})" for o in obs)
        raise InputError(
            f"LOGS: every run failed its automatic checks ({failed}); fly again, or give --keep-failed to "
            "count them in the bias fit anyway"
        )
    return counted


def _scenario_rows(
    m, obs: list[Observation], runs: PlanRuns, fc: DayForecast, counted: list[Observation]
) -> list[dict]:
    """One row per logged run: predicted, observed and corrected modes and sub-scores, path errors, the
    forecasts' mode probabilities (:func:`planner.review.forecast.run_forecast`) and the run's checks."""
    pred, corr, names = runs.pred, runs.corr, runs.pred.names
    base = runs.calib if runs.calib is not None else pred
    scen_rows = []
    for o in obs:
        k = runs.row_of[o.sid]
        p_traj, c_traj = runs.trajectories(o.sid)
        sub = {}
        for c in sorted(set(_level_cols(m, 1)) | {0, 1}):
            sub[names[c]] = {
                "predicted": _f(pred.scores[k, c]),
                "observed": _f(o.scores[c]) if o.scores is not None else None,
                "corrected": _f(corr.scores[k, c]),
            }
        scen_rows.append(
            {
                "id": o.sid,
                "log": o.run.path.name,
                "predicted_mode": MODE_NAMES[pred.modes[k]],
                "observed_mode": o.mode,
                "corrected_mode": MODE_NAMES[corr.modes[k]],
                "path_error_m": rms_path_error(o.run.track, p_traj),
                "path_error": path_error(o.run.track, p_traj),
                "path_error_corrected_m": rms_path_error(o.run.track, c_traj),
                "ended": o.run.ended or None,
                "steps": int(o.run.steps.shape[0]),
                "log_complete": bool(o.run.complete_file and o.run.has_end),
                "lost": list(o.run.problems),
                "frames_lost": o.run.frames_lost,
                "sub_scores": sub,
                "checks": summary_line(o.run.checks),
                "counted_in_bias_fit": any(o is c for c in counted),
            }
        )
        det = {s: MODE_NAMES[r.modes[k]] for s, r in (("planned", pred), ("uncorrected", base), ("corrected", corr))}
        scen_rows[-1]["forecast"] = run_forecast(fc.noise, fc.biased, o.sid, o.mode, det, fc.used)
        if runs.calib is not None:  # before (as planned) and after calibrating the vehicle model
            scen_rows[-1]["calibrated_mode"] = MODE_NAMES[runs.calib.modes[k]]
            scen_rows[-1]["path_error_calibrated_m"] = rms_path_error(o.run.track, runs.calibrated_trajectory(o.sid))
    return scen_rows


def _mode_agreement(scen_rows: list[dict]) -> dict:
    """Share of scenarios whose every observed run shows the predicted (the corrected) mode."""
    by_sid: dict[str, list[dict]] = {}
    for r in scen_rows:
        if r["observed_mode"] is not None:
            by_sid.setdefault(r["id"], []).append(r)
    agree_u = [all(r["predicted_mode"] == r["observed_mode"] for r in rs) for rs in by_sid.values()]
    agree_c = [all(r["corrected_mode"] == r["observed_mode"] for r in rs) for rs in by_sid.values()]
    agree_k = [all(r.get("calibrated_mode") == r["observed_mode"] for r in rs) for rs in by_sid.values()]
    calibrated = any("calibrated_mode" in r for r in scen_rows)
    return {
        "uncorrected": float(np.mean(agree_u)) if agree_u else None,
        "calibrated": float(np.mean(agree_k)) if agree_k and calibrated else None,
        "corrected": float(np.mean(agree_c)) if agree_c else None,
        "scenarios": len(by_sid),
        "runs_without_end": [r["log"] for r in scen_rows if r["observed_mode"] is None],
    }


def _pair_rows(
    plan: Plan, obs: list[Observation], runs: PlanRuns, bias, cfg: CompareConfig, fc: DayForecast
) -> tuple[list[dict], list[dict]]:
    """Per plan pair: did it straddle its boundary as observed, deterministically under the fitted bias, and
    with what probability under the corrected forecast; flagged by that probability, with an adjusted "M"
    scenario proposed (when the correction is used) for each side to move (:func:`_judge`)."""
    m, pred, corr, row_of = plan.mission, runs.pred, runs.corr, runs.row_of
    names = pred.names
    flown = {o.sid for o in obs}
    sens = plan.sensitivity()
    pair_rows, proposals = [], []
    for pair in plan.pairs:
        a, b = pair["scenarios"]
        cols = _elements(plan, pair, names)
        ka, kb = row_of[a], row_of[b]
        intended = {a: pred.scores[ka, cols], b: pred.scores[kb, cols]}
        biased = {a: corr.scores[ka, cols], b: corr.scores[kb, cols]}
        side = {s: _flown_as(plan, obs, s) for s in (a, b)}
        observed: dict[str, np.ndarray] = {}
        for s in (a, b):
            got = [o.scores for o in obs if o.sid == side[s] and o.mode is not None and o.scores is not None]
            if got:  # a mode comes with scores
                observed[s] = got[0][cols]
        # a side flown as its robust variant is judged against the variant's own prediction
        shown = {s: pred.scores[row_of[side[s]], cols] for s in (a, b)}
        row = {
            "id": pair["id"],
            "scenarios": [a, b],
            "flown": [side[a], side[b]],
            "elements": [names[c] for c in cols],
            "predicted_modes": [MODE_NAMES[pred.modes[ka]], MODE_NAMES[pred.modes[kb]]],
            "observed_modes": [_obs_mode(obs, side[a]), _obs_mode(obs, side[b])],
            "corrected_modes": [MODE_NAMES[corr.modes[ka]], MODE_NAMES[corr.modes[kb]]],
            "remaining": [s for s in (a, b) if side[s] not in flown],
        }
        if a in observed and b in observed:
            row["observed_straddles"] = bool(np.any(observed[a] != observed[b]))
            row["observed_as_predicted"] = bool(
                np.array_equal(observed[a], shown[a]) and np.array_equal(observed[b], shown[b])
            )
        else:
            row["observed_straddles"] = row["observed_as_predicted"] = None
        moved = [s for s in (a, b) if not np.array_equal(biased[s], intended[s])]
        row["straddles_under_bias"] = bool(np.any(biased[a] != biased[b]))
        row["moved_sides"] = moved
        outcome = sorted(set(cols) | {0, 1})  # the sides' outcomes: mode and the pair's elements
        row.update(fc.corrected.p_both(a, b, outcome, pred.scores[ka, outcome], pred.scores[kb, outcome]))
        adjust = _judge(row, moved, [names[c] for c in cols])
        if adjust and fc.used:
            for s in adjust:
                partner = b if s == a else a
                proposals.append(_proposal(m, runs, pair, s, partner, cols, intended[s], biased[s], bias, sens, cfg))
        pair_rows.append(row)
    return pair_rows, proposals


def _flown_as(plan: Plan, obs: list[Observation], sid: str) -> str:
    """The scenario flown for pair side ``sid``: itself when a run of it shows a mode, else its robust
    variant (``variant_of``) when one of those does (a range flies the variant the plan made), else ``sid``."""
    observed = {o.sid for o in obs if o.mode is not None}
    if sid in observed:
        return sid
    return next((v["id"] for v in plan.variants if v.get("variant_of") == sid and v["id"] in observed), sid)


def _judge(row: dict, moved: list[str], elements: list[str]) -> list[str]:
    """Flag the pair when it straddles with P below :data:`STRADDLE_BELOW` under the corrected forecast (the
    deterministic verdict, a side moved, stays beside it as ``flagged_deterministic``); the sides to adjust."""
    a, b = row["scenarios"]
    p, sides = row["p_straddles"], row["p_sides"]
    row["flagged_deterministic"] = bool(moved)
    row["flagged"] = bool(moved) if p is None else bool(p < STRADDLE_BELOW)
    if not row["flagged"]:
        return []
    why = []
    if p is not None:
        why.append(f"straddles with P {p:.2f} < {STRADDLE_BELOW:g} (sides {sides[0]:.2f}, {sides[1]:.2f})")
    if moved and not row["straddles_under_bias"]:
        why.append("both sides now show the same " + ", ".join(elements))
    elif moved:
        why.append("side(s) " + ", ".join(moved) + " no longer show their predicted " + ", ".join(elements))
    row["reason"] = "; ".join(why)
    if moved or p is None:
        return moved
    weak = [s for s, q in zip((a, b), sides) if q < STRADDLE_BELOW**0.5]  # a side no pair-mate can make up for
    return weak or [a if sides[0] <= sides[1] else b]


def _proposal(
    m,
    runs: PlanRuns,
    pair: dict,
    s: str,
    partner: str,
    cols: list[int],
    intended: np.ndarray,
    biased: np.ndarray,
    bias,
    sens: np.ndarray,
    cfg: CompareConfig,
) -> dict:
    """The adjusted scenario ``<s>M`` that shows side ``s``'s intended scores again under the bias, if one does."""
    names, U_plan = runs.pred.names, runs.U
    k = runs.row_of[s]
    found = adjust_for_bias(
        m,
        U_plan[k],
        U_plan[runs.row_of[partner]],
        cols,
        intended,
        bias,
        sens,
        dithers=cfg.dithers,
        p_target=cfg.p_target,
        seed=cfg.seed * 1000 + k,
    )
    prop = {
        "id": f"{s}M",
        "variant_of": s,
        "pair": pair["id"],
        "intended": {names[c]: _f(v) for c, v in zip(cols, intended)},
        "under_bias": {names[c]: _f(v) for c, v in zip(cols, biased)},
    }
    if found is None:
        prop.update(
            found=False,
            note="no move of up to 0.3 (unit cube) along the three most sensitive "
            "parameters restores it; choose a new pair",
        )
    else:
        v = np.array(found["u"])
        c = found["coordinate"]
        pname = m.parameter_of(c)
        before = m.space.decode(U_plan[k][None, :])[0][pname]
        after = m.space.decode(v[None, :])[0][pname]
        prop.update(
            found=True,
            u=found["u"],
            parameters=jsonable(m.space.decode(v[None, :])[0]),
            moved={
                "parameter": pname,
                "unit_step": found["unit_step"],
                "from": json_value(before),
                "to": json_value(after),
            },
            predicted_mode_under_bias=found["mode"],
            p_intended=found["p_intended"],
            robust=found["robust"],
        )
    return prop


def _remaining(plan: Plan, obs: list[Observation], runs: PlanRuns) -> list[dict]:
    """The plan's scenarios not flown yet, in run order, with their modes as planned and under the bias."""
    pred, corr, row_of = runs.pred, runs.corr, runs.row_of
    flown = {o.sid for o in obs}
    return [
        {
            "id": sid,
            "predicted_mode": MODE_NAMES[pred.modes[row_of[sid]]],
            "corrected_mode": MODE_NAMES[corr.modes[row_of[sid]]],
            "changed": bool(pred.modes[row_of[sid]] != corr.modes[row_of[sid]]),
        }
        for sid in plan.data.get("run_order", runs.ids)
        if sid in row_of and sid not in flown
    ]


def _biasfit_observed(fit, cfg: CompareConfig) -> dict:
    """How the bias was fitted: units, neutral values, residuals, convergence."""
    return {
        "units": dict(BIAS_UNITS),
        "neutral": dict(NEUTRAL),
        "fitted": list(cfg.fit),
        "priors": {n: p["prior"] for n, p in fit.to_dict().items()},
        "identified": [n for n, ok in fit.identified.items() if ok],
        "noise_scale": fit.estimate.noise_scale,
        "stderr_source": fit.estimate.stderr_sources,
        "bootstrap": fit.estimate.bootstrap,
        "end_conditions": fit.end_conditions,
        "rms_position_m": fit.rms_position_m,
        "rms_position_unbiased_m": fit.rms_position_neutral_m,
        "rms_energy_wh": fit.rms_energy_wh,
        "segments": fit.segments,
        "residuals": fit.residuals,
        "runs": fit.runs,
        "converged": fit.success,
        "message": fit.message,
        "correlation": fit.correlation,
    }


def _write(result: dict, plan: Plan, obs: list[Observation], runs: PlanRuns, out_dir: Path) -> None:
    """``comparison.json``, the report (``comparison.html`` and its figures) and the Foxglove overlays
    (``overlay_<scenario>.mcap``, listed in ``result["overlays"]``) into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    result["overlays"] = _write_overlays(result, plan, obs, runs, out_dir)
    write_text_atomic(out_dir / RESULT_NAME, json.dumps(result, indent=2))
    from planner.review.report import write_comparison_report

    traj = {o.sid: (*runs.trajectories(o.sid), runs.calibrated_trajectory(o.sid)) for o in obs}
    write_comparison_report(result, plan, [(o.sid, o.run.track) for o in obs], traj, out_dir)


def _write_overlays(result: dict, plan: Plan, obs: list[Observation], runs: PlanRuns, out_dir: Path) -> dict:
    """One Foxglove overlay per flown scenario (:func:`planner.review.overlay.write_overlay`): ``{scenario: file name}``."""
    from planner.review.overlay import overlay_name, write_overlay

    names = {}
    correction = {"correction_used": result["correction"]["used"], "note": result["correction"]["note"]}
    for sid in dict.fromkeys(o.sid for o in obs):
        flown = [o for o in obs if o.sid == sid]
        predicted, corrected = runs.trajectories(sid)
        tracks = {"predicted": predicted, "corrected": corrected, "calibrated": runs.calibrated_trajectory(sid)}
        observed = [(o.run.path.stem, o.run.track) for o in flown]
        checks = [(o.run.path.stem, o.run.checks) for o in flown]
        names[sid] = write_overlay(
            out_dir / overlay_name(sid), plan.mission, flown[0].u, observed, tracks, correction, checks
        ).name
    return names


def _level_cols(m, level: int) -> list[int]:
    tree = m.score_tree
    if level == 0:
        return list(tree.get("indices", [0, 1]))
    return [i for child in tree.get("children", []) for i in child.get("indices", [])]


def _obs_mode(obs: list[Observation], sid: str) -> str | None:
    modes = [o.mode for o in obs if o.sid == sid and o.mode is not None]
    return modes[0] if modes else None


def _f(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None
