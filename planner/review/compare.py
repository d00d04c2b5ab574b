"""After the range day: compare run logs with a plan's predictions, estimate the bias, re-plan.

``rapt-plan compare PLAN_DIR LOG.mcap...`` (section 4.6's first lesson: "an automatic way
to identify and apply this bias to our predictions").  :func:`compare`

1. reads every log (:mod:`planner.review.logs`; never modified, damaged ones as far as they go)
   and matches it to its plan scenario by the recorded metadata — a log of another
   mission or plan is refused with a one-line error;
2. rebuilds each run's track, scores it with the mission's own scorer and score tree
   (:func:`sim.uuv.replay.score_track`), and sets predicted against observed mode and
   sub-scores per scenario and per pair (did the pair straddle its boundary?), with the
   path error in metres against the predicted trajectory;
3. fits the execution bias (:mod:`sim.uuv.bias`) to all logs jointly (:mod:`planner.review.biasfit`):
   a MAP estimate under documented priors, each parameter with a standard error and whether
   the logs identify it (an unidentified one stays neutral), the runs' observed end
   conditions weighed in by a closed-loop re-simulation;
4. checks the correction before using it (:func:`cross_validate`): leave one log out, fit
   on the others, predict the left-out run's mode and path with and without the fitted
   bias.  The correction is used only when it predicts held-out runs at least as well in
   mode and better in mode or path; otherwise the report says "the logs do not support a
   correction; plan unchanged" and the corrected predictions are the uncorrected ones;
5. re-predicts every run and every plan scenario under the bias used — the corrected
   predictions — and flags the pairs that no longer straddle their boundary, with an
   adjusted "M" scenario for each side that moved (:mod:`planner.review.replan`);
6. writes ``comparison.json`` and ``comparison.html`` (:mod:`planner.review.report`), and per
   flown scenario an MCAP for Foxglove overlaying observed, predicted and corrected tracks
   (:mod:`planner.review.overlay`).
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

import sim.uuv
from planner.common.jsonio import json_value, jsonable
from planner.common.plans import Plan, load_plan
from planner.review.biasfit import BiasFit, check_end_conditions, fit_bias
from planner.review.logs import LogError, LoggedRun, read_run
from planner.review.replan import adjust_for_bias
from rapt.errors import InputError, StudyMismatchError
from sim.uuv.bias import BIAS_NAMES, BIAS_UNITS, NEUTRAL, Bias
from sim.uuv.mission import Vehicle
from sim.uuv.replay import score_track
from sim.uuv.scenario import make_scenarios
from sim.uuv.scoring import MODE_NAMES, mode_name

__all__ = ["compare", "CompareConfig", "COMPARISON_SCHEMA", "match_logs", "cross_validate", "NO_SUPPORT"]

COMPARISON_SCHEMA = "rapt.comparison/2"
#: What the report says when cross-validation does not support the fitted correction.
NO_SUPPORT = "the logs do not support a correction; plan unchanged"
#: Share by which the held-out path error must shrink for the correction to count as helping
#: on paths alone (a smaller change is within what refitting on other logs moves anyway).
PATH_GAIN = 0.1
RESULT_NAME = "comparison.json"
#: How the Foxglove overlays' file names begin (:func:`planner.review.overlay.overlay_name`).
OVERLAY_PREFIX = "overlay_"


@dataclass
class CompareConfig:
    dithers: int = 20  # stochastic runs checking each adjusted scenario (0: none)
    seed: int = 0
    fit: tuple[str, ...] = BIAS_NAMES  # bias parameters to fit; the others stay neutral
    p_target: float = 0.8
    bootstrap: int = 20  # block-bootstrap refits for the standard errors (0: analytic only)
    plant: Vehicle | None = None  # a calibrated vehicle (rapt-plan calibrate): flown in every prediction


@dataclass
class Observation:
    run: LoggedRun
    sid: str
    u: np.ndarray
    scores: np.ndarray | None = None
    mode: str | None = None  # None: the run's end is not in the log
    notes: list[str] = field(default_factory=list)


def match_logs(plan: Plan, runs: list[LoggedRun]) -> list[Observation]:
    """Each log's plan scenario, by its metadata; LogError naming the log that does not belong."""
    out = []
    for run in runs:
        meta, name = run.meta, run.path.name
        mission = meta.get("mission")
        if mission != plan.mission.name:
            raise LogError(
                f"LOG: {name} was flown on mission {mission!r}, but the plan is for "
                f"{plan.mission.name!r}; compare a plan only with the logs of its own runs"
            )
        pid = meta.get("plan_id") or ""
        if pid and pid != plan.id:
            raise LogError(
                f"LOG: {name} flew plan {pid}, not this plan ({plan.id}); give the plan directory "
                "its runs were flown from"
            )
        u = np.asarray(meta.get("u", []), dtype=float)
        sid = str(meta.get("scenario_id", ""))
        known = {s["id"]: np.asarray(s["u"], dtype=float) for s in plan.scenarios + plan.variants}
        if sid not in known or u.shape != known[sid].shape or not np.allclose(u, known[sid], rtol=0, atol=1e-9):
            same = [k for k, v in known.items() if u.shape == v.shape and np.allclose(u, v, rtol=0, atol=1e-9)]
            if not same:
                raise LogError(
                    f"LOG: {name} flew scenario {sid!r}, which is not a scenario of this plan (no plan "
                    "scenario has its parameters); fly it with rapt-plan run PLAN/plan.json --scenario ID"
                )
            sid = same[0]
        out.append(Observation(run, sid, known[sid]))
    return out


def _elements(plan: Plan, pair: dict, names: list[str]) -> list[int]:
    """Score columns a pair tests: its elements, and on the root level both root scores (the
    mode), so an adjusted pair tests the same boundary type as planned (TF/SS, not TF/TS)."""
    cols = [names.index(e) for e in pair.get("elements", []) if e in names]
    if not cols or pair.get("level", 0) == 0:
        cols = sorted(set(cols) | {0, 1})
    return cols


def _path_error(track: np.ndarray, pred: np.ndarray | None) -> dict | None:
    """Horizontal distance between a logged and a predicted track at the same times (m)."""
    if pred is None or track.shape[0] == 0:
        return None
    n = min(track.shape[0], pred.shape[0])
    d = np.hypot(track[:n, 1] - pred[:n, 1], track[:n, 2] - pred[:n, 2])
    return {
        "rms_m": float(np.sqrt(np.mean(d**2))),
        "max_m": float(d.max()),
        "compared_s": float(track[n - 1, 0]),
        "duration_observed_s": float(track[-1, 0]),
        "duration_predicted_s": float(pred[-1, 0]),
    }


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
    ids, U_plan, pred = _predict_plan(plan)
    say("scoring logged runs")
    _score_observed(m, obs)
    plant = cfg.plant
    calib = None
    if plant is not None:
        say("predicting with the calibrated vehicle")
        calib = sim.uuv.simulate(m, U_plan, trajectories=True, plant=plant)
    baseline = calib if calib is not None else pred
    say("fitting the execution bias")
    start_times = [float(make_scenarios(m, o.u[None, :]).start_time[0]) for o in obs]
    fit = _fit(m, obs, start_times, cfg, cfg.bootstrap)
    say("cross-validating the correction")
    cv = cross_validate(m, obs, start_times, baseline, _rows(ids), cfg)
    bias_used = fit.bias if cv["correction_used"] else Bias()
    say("re-predicting under the fitted bias")
    corr = (
        sim.uuv.simulate(m, U_plan, trajectories=True, bias=bias_used, plant=cfg.plant)
        if cv["correction_used"]
        else baseline
    )
    plan_runs = _PlanRuns(ids, U_plan, pred, corr, calib)
    scen_rows = _scenario_rows(m, obs, plan_runs)
    agreement = _mode_agreement(scen_rows)
    say("re-planning")
    pair_rows, proposals = _pair_rows(plan, obs, plan_runs, bias_used, cfg)
    result = {
        "schema": COMPARISON_SCHEMA,
        "plan": {"id": plan.id, "path": str(plan.path), "mission": m.name, "mission_file": str(plan.mission_file)},
        "logs": [
            {
                "path": str(o.run.path),
                "scenario": o.sid,
                "messages": o.run.messages,
                "complete": bool(o.run.complete_file and o.run.has_end),
                "lost": o.run.problems,
                "frames_lost": o.run.frames_lost,
                "losses": o.run.losses if o.run.losses is not None else "unknown",
            }
            for o in obs
        ],
        "bias": fit.to_dict(),
        "bias_fit": _bias_fit(fit, cfg),
        "calibrated_vehicle": None if plant is None else jsonable(dataclasses.asdict(plant)),
        "cross_validation": cv,
        "correction": {
            "used": cv["correction_used"],
            "bias": bias_used.to_dict(),
            "note": cv["note"],
        },
        "scenarios": scen_rows,
        "mode_agreement": agreement,
        "pairs": pair_rows,
        "remaining": _remaining(plan, obs, plan_runs),
        "proposals": proposals,
    }
    if out_dir is not None:
        say("writing the report")
        _write(result, plan, obs, plan_runs, Path(out_dir))
    return result


def _fit(m, obs: list[Observation], start_times: list[float], cfg: CompareConfig, bootstrap: int) -> BiasFit:
    """The bias fit of ``obs``'s logs, its bias chosen against their observed end conditions."""
    runs = [o.run for o in obs]
    fit = fit_bias(m, runs, start_times, fit=tuple(cfg.fit), bootstrap=bootstrap, seed=cfg.seed, vehicle=cfg.plant)
    ends = [o.scores if o.mode is not None else None for o in obs]
    U = np.array([o.u for o in obs])
    return check_end_conditions(m, fit, runs, start_times, U, ends, seed=cfg.seed, vehicle=cfg.plant)


def cross_validate(
    m,
    obs: list[Observation],
    start_times: list[float],
    pred: sim.uuv.Result,
    row_of: dict[str, int],
    cfg: CompareConfig,
) -> dict:
    """Leave one log out: fit on the others, predict the left-out run's mode and path with and
    without that bias; and whether the correction is to be used (module docstring, step 4).
    ``pred`` are the predictions without a bias (with the calibrated vehicle when there is one)."""
    folds = []
    for i, o in enumerate(obs):
        rest = [j for j in range(len(obs)) if j != i]
        row: dict = {"log": o.run.path.name, "scenario": o.sid, "observed_mode": o.mode}
        k = row_of[o.sid]
        row["uncorrected_mode"] = MODE_NAMES[pred.modes[k]]
        row["path_error_uncorrected_m"] = _round(_path_error(o.run.track, pred.trajectory(k)), "rms_m")
        try:
            if not rest:
                raise InputError("no other log to fit on")
            fit = _fit(m, [obs[j] for j in rest], [start_times[j] for j in rest], cfg, 0)
        except InputError as exc:
            row.update(corrected_mode=None, path_error_corrected_m=None, bias=None, note=str(exc))
            folds.append(row)
            continue
        r = sim.uuv.simulate(m, o.u[None, :], trajectories=True, bias=fit.bias, plant=cfg.plant)
        row["corrected_mode"] = MODE_NAMES[r.modes[0]] if r.valid[0] else "invalid"
        row["path_error_corrected_m"] = _round(_path_error(o.run.track, r.trajectory(0)), "rms_m")
        row["bias"] = {n: v for n, v in fit.bias.to_dict().items() if v != NEUTRAL[n]}
        folds.append(row)
    scored = [f for f in folds if f["observed_mode"] is not None and f["corrected_mode"] is not None]
    pathed = [f for f in folds if f["path_error_uncorrected_m"] is not None and f["path_error_corrected_m"] is not None]
    agree_u = float(np.mean([f["uncorrected_mode"] == f["observed_mode"] for f in scored])) if scored else None
    agree_c = float(np.mean([f["corrected_mode"] == f["observed_mode"] for f in scored])) if scored else None
    path_u = float(np.mean([f["path_error_uncorrected_m"] for f in pathed])) if pathed else None
    path_c = float(np.mean([f["path_error_corrected_m"] for f in pathed])) if pathed else None
    used, note = _support(agree_u, agree_c, path_u, path_c)
    return {
        "folds": folds,
        "held_out_mode_agreement": {"uncorrected": agree_u, "corrected": agree_c, "runs": len(scored)},
        "held_out_path_error_m": {"uncorrected": path_u, "corrected": path_c, "runs": len(pathed)},
        "correction_used": used,
        "note": note,
    }


def _support(agree_u, agree_c, path_u, path_c) -> tuple[bool, str]:
    """Use the correction only when held-out runs show it helps: mode agreement no worse, and
    better mode agreement or a path error at least :data:`PATH_GAIN` smaller."""
    if agree_c is None and path_c is None:
        return False, NO_SUPPORT + " (no held-out prediction: give at least two logs)"
    if agree_c is not None and agree_u is not None and agree_c < agree_u:
        return (
            False,
            NO_SUPPORT + f" (held-out mode agreement {agree_c:.0%} corrected against {agree_u:.0%} uncorrected)",
        )
    better_mode = agree_c is not None and agree_u is not None and agree_c > agree_u
    better_path = path_c is not None and path_u is not None and path_c < (1.0 - PATH_GAIN) * path_u
    if not (better_mode or better_path):
        return False, NO_SUPPORT + " (the correction does not improve held-out predictions)"
    parts = []
    if agree_c is not None and agree_u is not None:
        parts.append(f"held-out mode agreement {agree_u:.0%} -> {agree_c:.0%}")
    if path_c is not None and path_u is not None:
        parts.append(f"held-out path error {path_u:.1f} -> {path_c:.1f} m")
    return True, "correction used: " + ", ".join(parts)


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


@dataclass
class _PlanRuns:
    """Every plan scenario (and variant): its unit-cube row, its run as planned and under the fitted bias
    (both simulated with their trajectories)."""

    ids: list[str]
    U: np.ndarray
    pred: sim.uuv.Result
    corr: sim.uuv.Result
    calib: sim.uuv.Result | None = None  # with the calibrated vehicle, no bias (when one is given)

    @cached_property
    def row_of(self) -> dict[str, int]:
        """The row of each scenario id."""
        return _rows(self.ids)

    def trajectories(self, sid: str) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Scenario ``sid``'s predicted and corrected trajectories (None when it is invalid)."""
        k = self.row_of[sid]
        return self.pred.trajectory(k), self.corr.trajectory(k)

    def calibrated_trajectory(self, sid: str) -> np.ndarray | None:
        """Scenario ``sid``'s trajectory with the calibrated vehicle (None without one, or when invalid)."""
        return None if self.calib is None else self.calib.trajectory(self.row_of[sid])


def _rows(ids: list[str]) -> dict[str, int]:
    return {sid: k for k, sid in enumerate(ids)}


def _predict_plan(plan: Plan) -> tuple[list[str], np.ndarray, sim.uuv.Result]:
    """Predictions of every plan scenario, unbiased, as planned: ids, unit-cube rows and the runs (with
    trajectories); StudyMismatchError when they are not the plan's."""
    m = plan.mission
    ids = [s["id"] for s in plan.scenarios + plan.variants]
    U_plan = np.array([plan.u(i) for i in ids]).reshape(-1, m.dim)
    pred = sim.uuv.simulate(m, U_plan, trajectories=True)
    row_of = _rows(ids)
    for s in plan.scenarios + plan.variants:
        planned = s.get("predicted", {}).get("mode")
        got = MODE_NAMES[pred.modes[row_of[s["id"]]]] if pred.valid[row_of[s["id"]]] else "invalid"
        if planned and planned != got:
            raise StudyMismatchError(
                f"PLAN: scenario {s['id']} is predicted {got} by {plan.mission.source} but the plan says "
                f"{planned}; the mission or the simulator changed since the plan was made — regenerate the plan"
            )
    return ids, U_plan, pred


def _score_observed(m, obs: list[Observation]) -> None:
    """Each logged run's scores from its track, and its mode when the run's end is in the log."""
    for o in obs:
        if o.run.steps.shape[0]:
            o.scores = score_track(m, o.u, o.run.track, o.run.wp_aborted, o.run.return_reason)
            if o.run.has_end:
                o.mode = mode_name(o.scores)


def _scenario_rows(m, obs: list[Observation], runs: _PlanRuns) -> list[dict]:
    """One row per logged run: predicted, observed and corrected modes and sub-scores, path errors."""
    pred, corr, names = runs.pred, runs.corr, runs.pred.names
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
                "path_error_m": _round(_path_error(o.run.track, p_traj), "rms_m"),
                "path_error": _path_error(o.run.track, p_traj),
                "path_error_corrected_m": _round(_path_error(o.run.track, c_traj), "rms_m"),
                "ended": o.run.ended or None,
                "steps": int(o.run.steps.shape[0]),
                "log_complete": bool(o.run.complete_file and o.run.has_end),
                "lost": list(o.run.problems),
                "frames_lost": o.run.frames_lost,
                "sub_scores": sub,
            }
        )
        if runs.calib is not None:  # before (as planned) and after calibrating the vehicle model
            scen_rows[-1]["calibrated_mode"] = MODE_NAMES[runs.calib.modes[k]]
            scen_rows[-1]["path_error_calibrated_m"] = _round(
                _path_error(o.run.track, runs.calibrated_trajectory(o.sid)), "rms_m"
            )
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
    plan: Plan, obs: list[Observation], runs: _PlanRuns, bias, cfg: CompareConfig
) -> tuple[list[dict], list[dict]]:
    """Per plan pair: did it straddle its boundary as observed and under the fitted bias; and an
    adjusted "M" scenario proposed for each side the bias moved."""
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
        observed: dict[str, np.ndarray] = {}
        for o in obs:
            if o.sid in (a, b) and o.mode is not None and o.scores is not None:  # a mode comes with scores
                observed.setdefault(o.sid, o.scores[cols])
        row = {
            "id": pair["id"],
            "scenarios": [a, b],
            "elements": [names[c] for c in cols],
            "predicted_modes": [MODE_NAMES[pred.modes[ka]], MODE_NAMES[pred.modes[kb]]],
            "observed_modes": [_obs_mode(obs, a), _obs_mode(obs, b)],
            "corrected_modes": [MODE_NAMES[corr.modes[ka]], MODE_NAMES[corr.modes[kb]]],
            "remaining": [s for s in (a, b) if s not in flown],
        }
        if a in observed and b in observed:
            row["observed_straddles"] = bool(np.any(observed[a] != observed[b]))
            row["observed_as_predicted"] = bool(
                np.array_equal(observed[a], intended[a]) and np.array_equal(observed[b], intended[b])
            )
        else:
            row["observed_straddles"] = row["observed_as_predicted"] = None
        moved = [s for s in (a, b) if not np.array_equal(biased[s], intended[s])]
        row["straddles_under_bias"] = bool(np.any(biased[a] != biased[b]))
        row["flagged"] = bool(moved)
        row["moved_sides"] = moved
        if moved:
            why = (
                "both sides now show the same " + ", ".join(names[c] for c in cols)
                if not row["straddles_under_bias"]
                else "side(s) "
                + ", ".join(moved)
                + " no longer show their predicted "
                + ", ".join(names[c] for c in cols)
            )
            row["reason"] = why
            for s in moved:
                partner = b if s == a else a
                proposals.append(_proposal(m, runs, pair, s, partner, cols, intended[s], biased[s], bias, sens, cfg))
        pair_rows.append(row)
    return pair_rows, proposals


def _proposal(
    m,
    runs: _PlanRuns,
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


def _remaining(plan: Plan, obs: list[Observation], runs: _PlanRuns) -> list[dict]:
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


def _bias_fit(fit, cfg: CompareConfig) -> dict:
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


def _write(result: dict, plan: Plan, obs: list[Observation], runs: _PlanRuns, out_dir: Path) -> None:
    """``comparison.json``, the report (``comparison.html`` and its figures) and the Foxglove overlays
    (``overlay_<scenario>.mcap``, listed in ``result["overlays"]``) into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    result["overlays"] = _write_overlays(result, plan, obs, runs, out_dir)
    (out_dir / RESULT_NAME).write_text(json.dumps(result, indent=2))
    from planner.review.report import write_comparison_report

    traj = {o.sid: (*runs.trajectories(o.sid), runs.calibrated_trajectory(o.sid)) for o in obs}
    write_comparison_report(result, plan, [(o.sid, o.run.track) for o in obs], traj, out_dir)


def _write_overlays(result: dict, plan: Plan, obs: list[Observation], runs: _PlanRuns, out_dir: Path) -> dict:
    """One Foxglove overlay per flown scenario (:func:`planner.review.overlay.write_overlay`): ``{scenario: file name}``."""
    from planner.review.overlay import overlay_name, write_overlay

    names = {}
    correction = {"correction_used": result["correction"]["used"], "note": result["correction"]["note"]}
    for sid in dict.fromkeys(o.sid for o in obs):
        flown = [o for o in obs if o.sid == sid]
        predicted, corrected = runs.trajectories(sid)
        tracks = {"predicted": predicted, "corrected": corrected, "calibrated": runs.calibrated_trajectory(sid)}
        observed = [(o.run.path.stem, o.run.track) for o in flown]
        names[sid] = write_overlay(
            out_dir / overlay_name(sid), plan.mission, flown[0].u, observed, tracks, correction
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


def _round(d: dict | None, key: str) -> float | None:
    return None if d is None else round(d[key], 3)
