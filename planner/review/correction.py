"""Whether the logs support a bias correction: fit the bias, then predict each log from the others.

A bias fitted to a handful of runs may only fit their noise.  :func:`cross_validate` leaves
one log out at a time, fits the bias to the others (:func:`fit_observed`) and predicts the
left-out run's mode and path with and without it; :func:`correction_support` uses the
correction only when it predicts held-out runs at least as well in mode and better in mode
or path (module docstring of :mod:`planner.review.compare`, step 4).
"""

from __future__ import annotations

import numpy as np

import sim.uuv
from planner.review.biasfit import BiasFit, check_end_conditions, fit_bias
from planner.review.runs import CompareConfig, Observation
from rapt.errors import InputError
from sim.uuv.bias import NEUTRAL
from sim.uuv.scoring import MODE_NAMES

__all__ = [
    "NO_SUPPORT",
    "PATH_GAIN",
    "path_error",
    "rms_path_error",
    "fit_observed",
    "cross_validate",
    "correction_support",
]

#: What the report says when cross-validation does not support the fitted correction.
NO_SUPPORT = "the logs do not support a correction; plan unchanged"
#: Share by which the held-out path error must shrink for the correction to count as helping
#: on paths alone (a smaller change is within what refitting on other logs moves anyway).
PATH_GAIN = 0.1


def path_error(track: np.ndarray, pred: np.ndarray | None) -> dict | None:
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


def rms_path_error(track: np.ndarray, pred: np.ndarray | None) -> float | None:
    """The RMS of :func:`path_error` (m, to the millimetre), None when there is nothing to compare."""
    d = path_error(track, pred)
    return None if d is None else round(d["rms_m"], 3)


def fit_observed(m, obs: list[Observation], start_times: list[float], cfg: CompareConfig, bootstrap: int) -> BiasFit:
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
        row["path_error_uncorrected_m"] = rms_path_error(o.run.track, pred.trajectory(k))
        try:
            if not rest:
                raise InputError("no other log to fit on")
            fit = fit_observed(m, [obs[j] for j in rest], [start_times[j] for j in rest], cfg, 0)
        except InputError as exc:
            row.update(corrected_mode=None, path_error_corrected_m=None, bias=None, note=str(exc))
            folds.append(row)
            continue
        r = sim.uuv.simulate(m, o.u[None, :], trajectories=True, bias=fit.bias, plant=cfg.plant)
        row["corrected_mode"] = MODE_NAMES[r.modes[0]] if r.valid[0] else "invalid"
        row["path_error_corrected_m"] = rms_path_error(o.run.track, r.trajectory(0))
        row["bias"] = {n: v for n, v in fit.bias.to_dict().items() if v != NEUTRAL[n]}
        folds.append(row)
    scored = [f for f in folds if f["observed_mode"] is not None and f["corrected_mode"] is not None]
    pathed = [f for f in folds if f["path_error_uncorrected_m"] is not None and f["path_error_corrected_m"] is not None]
    agree_u = float(np.mean([f["uncorrected_mode"] == f["observed_mode"] for f in scored])) if scored else None
    agree_c = float(np.mean([f["corrected_mode"] == f["observed_mode"] for f in scored])) if scored else None
    path_u = float(np.mean([f["path_error_uncorrected_m"] for f in pathed])) if pathed else None
    path_c = float(np.mean([f["path_error_corrected_m"] for f in pathed])) if pathed else None
    used, note = correction_support(agree_u, agree_c, path_u, path_c)
    return {
        "folds": folds,
        "held_out_mode_agreement": {"uncorrected": agree_u, "corrected": agree_c, "runs": len(scored)},
        "held_out_path_error_m": {"uncorrected": path_u, "corrected": path_c, "runs": len(pathed)},
        "correction_used": used,
        "note": note,
    }


def correction_support(agree_u, agree_c, path_u, path_c) -> tuple[bool, str]:
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
