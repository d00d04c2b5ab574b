"""Calibrate a mission's vehicle block from logged runs: ``rapt-plan calibrate MISSION.toml LOG.mcap... --out F.toml``.

A vehicle whose dynamics differ from the mission file's (a real vehicle, another vehicle
model) shows steady differences that no execution bias (:mod:`sim.uuv.bias`) describes:
the speed it reaches per commanded speed, how fast it turns, how much energy a metre
costs.  :func:`calibrate` fits the observable properties of the ``[vehicle]`` block
(:data:`FITTED`) to logs flown by any autonomy:

- every log is cut into short open-loop segments replayed on the logged set-points from
  the logged state (:mod:`planner.review.segments`), so no autonomy decision sits inside a
  prediction and the fit is smooth in the parameters;
- the residuals are the predicted minus logged positions (:data:`SIGMA_POSITION_M`),
  headings (wrapped, :data:`SIGMA_HEADING_DEG`) and energy used (:data:`SIGMA_ENERGY_WH`),
  each kind weighted by its own robust noise scale, so a precise kind is not drowned by
  a noisy one;
- the estimate is the maximum a posteriori fit of :func:`rapt.mapfit.fit_map` under one
  prior per property centred on the file's value, :data:`PRIOR_SHARE` of it wide (what a
  test engineer would accept a datasheet to be off by), with standard errors that hold
  when a run's residuals move together (cluster-robust and a block bootstrap by run,
  :func:`planner.review.biasfit.bootstrap_blocks`), plus, for vehicle-paced runs, the replay's
  own approximation (:data:`MODEL_SHARE_PACED`);
- a property the logs do not identify (its posterior not clearly narrower than its
  prior: ``max_speed`` when no command asked for more than the vehicle reaches, the
  hotel load when the vehicle never changed speed) keeps the file's value and is flagged.

Not fitted, and why: ``cruise_speed`` is what the autonomy commands (a choice, not a
property of the vehicle; ``speed_gain`` carries what the vehicle makes of it);
``battery_wh``, ``start_battery``, ``reserve_factor`` and ``critical_battery`` are the
range's and the autonomy's settings, not seen in a track; the sonar and navigation noise
(``sonar_*``, ``ins_drift_m_per_s``, ``gps_sigma_m``) and ``sway_damping`` leave no
steady trace in position and energy a few minutes long.  The tide and the clock are taken
as the mission file says: fit an execution bias with ``rapt-plan compare`` for those.

The output is the input mission file with only the fitted ``[vehicle]`` values changed
(comments and layout kept), a comment block at its top naming the logs and each fitted
value with its standard error, and a JSON sidecar (``--out`` with ``.json``) with the
estimates, standard errors, priors and residual RMS before and after.  Both are
deterministic.  Inputs are only read.  Bad inputs are one-line errors naming the problem.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planner.review.biasfit import bootstrap_blocks
from planner.review.logs import LogError, read_run
from planner.review.segments import MAX_STEP_SHARE, SEGMENT_STEPS, Segments, replay, replayable_steps, segment_batch
from rapt.errors import InputError
from rapt.mapfit import MapEstimate, Prior, fit_map
from sim.uuv.angles import wrap_angle
from sim.uuv.mission import Mission, Vehicle
from sim.uuv.missionfile import load_mission
from sim.uuv.scenario import make_scenarios

__all__ = [
    "Calibration",
    "calibrate",
    "fit_vehicle",
    "vehicle_priors",
    "FITTED",
    "MIN_LOGS",
    "CALIBRATION_SCHEMA",
]

CALIBRATION_SCHEMA = "rapt.calibration/1"

#: The ``[vehicle]`` fields fitted, in this order.
FITTED: tuple[str, ...] = (
    "speed_gain",
    "max_speed",
    "surge_time_constant_s",
    "max_turn_rate_dps",
    "yaw_time_constant_s",
    "hotel_w",
    "drag_w",
)
UNITS = {
    "speed_gain": "x",
    "max_speed": "m/s",
    "surge_time_constant_s": "s",
    "max_turn_rate_dps": "deg/s",
    "yaw_time_constant_s": "s",
    "hotel_w": "W",
    "drag_w": "W",
}
#: Fewest logs a calibration takes.  One run's segments share one tide phase, one route
#: and one navigation drift, so its errors cannot be told from the vehicle's; a second,
#: independent run is the least that lets the standard errors (which resample runs or
#: blocks of segments) see how much the estimate moves from run to run.
MIN_LOGS = 2
#: Prior s.d. as a share of the file's value: a datasheet or an earlier calibration
#: that is 30 % off is what a test engineer would still accept; larger errors are found
#: when the logs show them clearly.
PRIOR_SHARE = 0.3
#: Smallest prior s.d. per field (a file value of 0 still gets a usable prior).
PRIOR_SD_FLOOR = {
    "speed_gain": 0.05,
    "max_speed": 0.1,
    "surge_time_constant_s": 0.3,
    "max_turn_rate_dps": 1.0,
    "yaw_time_constant_s": 0.3,
    "hotel_w": 5.0,
    "drag_w": 10.0,
}
#: Upper bound of the power terms (W): the logs decide within it, however far from the file.
POWER_HIGH_W = 20000.0
#: Residual units: metres of position, degrees of heading, watt-hours of energy used.
SIGMA_POSITION_M = 1.0
SIGMA_HEADING_DEG = 2.0
SIGMA_ENERGY_WH = 0.05
#: Share of a value added (in quadrature) to its standard error when vehicle-paced runs are
#: fitted: the replay's own approximation of a continuously moving vehicle (sub-steps,
#: heading and energy reports a fraction of a second older than the position) biases the
#: estimates by up to about this much on the bare-autopilot front-seat, which the
#: statistical standard errors do not see.
MODEL_SHARE_PACED = 0.03
#: Bootstrap refits for the standard errors (0: analytic ones only).
BOOTSTRAP = 20
#: Significant digits of a calibrated value in the written file.
DIGITS = 5


def vehicle_priors(vehicle: Vehicle, names: Sequence[str] = FITTED) -> list[Prior]:
    """One prior per field: centred on the file's value, :data:`PRIOR_SHARE` of it wide.

    Bounds keep the file loadable and the model physical: positive time constants and
    rates, power terms >= 0 (and up to :data:`POWER_HIGH_W`: a thruster vehicle's pack may
    draw ten times a torpedo's), ``max_speed`` >= ``cruise_speed`` (the mission file's rule).
    """
    out = []
    for n in names:
        c = float(getattr(vehicle, n))
        sd = max(PRIOR_SHARE * abs(c), PRIOR_SD_FLOOR[n])
        if n == "max_speed":
            low, high = float(vehicle.cruise_speed), max(4.0 * c, c + 4 * sd)
        elif n in ("hotel_w", "drag_w"):  # a real pack may draw kilowatts where the file says watts
            low, high = 0.0, max(POWER_HIGH_W, 50.0 * c)
        else:
            low, high = min(c / 5.0, c), max(5.0 * c, c + 5 * sd)
            low = max(low, 1e-3)
        out.append(Prior(n, c, sd, min(low, c), high))
    return out


@dataclass
class Calibration:
    """A fitted vehicle block and the fit behind it (see :func:`fit_vehicle`)."""

    vehicle: Vehicle  # the file's vehicle with the identified fields replaced
    original: Vehicle
    estimate: MapEstimate
    rms_before: dict[str, float]  # position_m, heading_deg, energy_wh under the file's vehicle
    rms_after: dict[str, float]  # the same under the calibrated vehicle
    segments: int
    runs: int
    logs: list[dict] = field(default_factory=list)  # name, sha256, scenario, steps (calibrate only)
    model_share: float = 0.0  # share of each value added to its s.e. for the replay's approximation

    @property
    def fitted(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.estimate.priors)

    @property
    def stderr(self) -> dict[str, float]:
        """Per fitted field: the fit's standard error, with :attr:`model_share` of the value added in quadrature."""
        est = self.estimate
        return {
            n: float(np.hypot(est.stderr[n], self.model_share * abs(getattr(self.vehicle, n))))
            if est.identified[n]
            else float(est.stderr[n])
            for n in self.fitted
        }

    def to_dict(self) -> dict:
        """What the JSON sidecar holds (no paths beyond the logs' names, no times: deterministic)."""
        est, se = self.estimate, self.stderr
        params = {}
        for p in est.priors:
            n = p.name
            params[n] = {
                "file_value": float(getattr(self.original, n)),
                "calibrated": float(getattr(self.vehicle, n)),
                "stderr": se[n],
                "stderr_fit": float(est.stderr[n]),
                "identified": bool(est.identified[n]),
                "map_estimate": float(est.map_value[n]),
                "stderr_source": est.stderr_sources.get(n, ""),
                "unit": UNITS[n],
                "prior": {"centre": p.centre, "sd": p.sd, "low": p.low, "high": p.high},
            }
        return {
            "schema": CALIBRATION_SCHEMA,
            "parameters": params,
            "not_fitted": [f.name for f in dataclasses.fields(Vehicle) if f.name not in self.fitted],
            "residual_rms": {"before": self.rms_before, "after": self.rms_after},
            "residual_sigmas": {
                "position_m": SIGMA_POSITION_M,
                "heading_deg": SIGMA_HEADING_DEG,
                "energy_wh": SIGMA_ENERGY_WH,
            },
            "correlation": est.correlation,
            "model_share": self.model_share,
            "segments": self.segments,
            "runs": self.runs,
            "bootstrap": est.bootstrap,
            "fit_converged": est.success,
            "logs": self.logs,
        }


def _residual_parts(mission: Mission, seg: Segments, vehicle: Vehicle) -> tuple[np.ndarray, ...]:
    """Position (m, east and north), heading (deg) and energy (Wh) errors of every valid segment step."""
    px, py, pe, ph = replay(mission, seg, vehicle=vehicle)
    v = seg.valid
    dh = np.rad2deg(wrap_angle(ph - seg.obs_heading))
    return (px - seg.obs_x)[v], (py - seg.obs_y)[v], dh[v], (pe - seg.obs_energy_wh)[v]


def _rms(parts: tuple[np.ndarray, ...]) -> dict[str, float]:
    dx, dy, dh, de = parts
    return {
        "position_m": float(np.sqrt(np.mean(dx**2 + dy**2))),
        "heading_deg": float(np.sqrt(np.mean(dh**2))),
        "energy_wh": float(np.sqrt(np.mean(de**2))),
    }


def fit_vehicle(
    mission: Mission,
    runs: list,
    start_times: Sequence[float],
    fit: Sequence[str] = FITTED,
    *,
    bootstrap: int = BOOTSTRAP,
    seed: int = 0,
    length: int = SEGMENT_STEPS,
) -> Calibration:
    """MAP fit of the ``[vehicle]`` fields ``fit`` to ``runs`` (:class:`planner.review.logs.LoggedRun`-like)
    flown from scenario start times ``start_times``; priors centred on ``mission.vehicle``."""
    names = tuple(n for n in FITTED if n in fit)
    unknown = [n for n in fit if n not in FITTED]
    if unknown or not names:
        raise InputError(
            f"fit: unknown vehicle field {unknown[0] if unknown else fit!r}; choose from {', '.join(FITTED)}"
        )
    seg = segment_batch(mission, runs, list(start_times), length)
    if not seg.valid.any():
        raise InputError("LOGS: no replayable flight in the logs (no telemetry steps with set-points); nothing to fit")
    base = mission.vehicle

    def vehicle_of(theta: np.ndarray) -> Vehicle:
        return dataclasses.replace(base, **{n: float(v) for n, v in zip(names, theta)})

    def residuals(theta: np.ndarray) -> np.ndarray:
        dx, dy, dh, de = _residual_parts(mission, seg, vehicle_of(theta))
        return np.concatenate(
            [dx / SIGMA_POSITION_M, dy / SIGMA_POSITION_M, dh / SIGMA_HEADING_DEG, de / SIGMA_ENERGY_WH]
        )

    per_step = np.nonzero(seg.valid)[0]
    blocks = bootstrap_blocks(seg)[per_step]
    est = fit_map(
        residuals,
        vehicle_priors(base, names),
        groups=np.concatenate([blocks] * 4),
        kinds=np.repeat(np.array(["position", "position", "heading", "energy"]), per_step.size),
        bootstrap=bootstrap,
        seed=seed,
    )
    calibrated = vehicle_of(np.array([est.value[n] for n in names]))
    paced = seg.substeps is not None and bool(np.any(seg.substeps > 1))
    return Calibration(
        calibrated,
        base,
        est,
        _rms(_residual_parts(mission, seg, base)),
        _rms(_residual_parts(mission, seg, calibrated)),
        int(seg.valid.shape[0]),
        int(len(set(seg.run.tolist()))),
        model_share=MODEL_SHARE_PACED if paced else 0.0,
    )


# -- the command ------------------------------------------------------------------------
def sidecar_path(out_path: str | Path) -> Path:
    """The JSON written beside ``out_path`` (same name, ``.json``)."""
    return Path(out_path).with_suffix(".json")


def _check_paths(mission_path: Path, log_paths: Sequence[Path], out_path: Path) -> None:
    """One-line InputError for an --out that would overwrite an input, or too few logs; runs before any reading."""
    inputs = {p.resolve() for p in (mission_path, *log_paths)}
    for target in (out_path, sidecar_path(out_path)):
        if target.resolve() in inputs:
            raise InputError(f"--out: writing {target} would overwrite an input; choose another file name")
    if out_path.suffix != ".toml":
        raise InputError(
            f"--out: {out_path} is not a .toml file; name the calibrated mission file e.g. calibrated.toml"
        )
    if len(log_paths) < MIN_LOGS:
        raise InputError(
            f"LOGS: {len(log_paths)} log(s) given; a calibration needs at least {MIN_LOGS} runs "
            "(one run's errors cannot be told from the vehicle's); give more .mcap logs"
        )
    if len({p.resolve() for p in log_paths}) < len(log_paths):
        raise InputError("LOGS: a log is given twice; give each run's log once")


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _start_time(mission: Mission, run, name: str) -> float:
    """The scenario start time of a logged run (sets the tide), from its unit-cube row."""
    u = np.asarray(run.meta.get("u", []), dtype=float).ravel()
    if u.shape != (mission.dim,):
        raise LogError(
            f"LOG: {name} has no scenario row of mission {mission.name!r} in its metadata "
            f"(u has {u.size} values, the mission {mission.dim}); give logs written by rapt-plan run"
        )
    scen = make_scenarios(mission, u[None, :])
    if not scen.valid[0]:
        raise LogError(f"LOG: {name} flew an invalid scenario ({scen.invalid_reason[0]}); it cannot be replayed")
    return float(scen.start_time[0])


def _replayable_steps(run, dt: float) -> int:
    return int(np.sum(replayable_steps(run, dt)))


def calibrate(
    mission_path: str | Path,
    log_paths: Sequence[str | Path],
    out_path: str | Path,
    *,
    fit: Sequence[str] = FITTED,
    seed: int = 0,
    bootstrap: int = BOOTSTRAP,
) -> Calibration:
    """Fit the mission's vehicle block to the logs and write ``out_path`` and its JSON sidecar (module docstring).

    Refused with a one-line error before anything is written: fewer than :data:`MIN_LOGS`
    logs, a log given twice, an ``out_path`` that is not ``.toml`` or would overwrite an
    input, a log that is unreadable, of another mission, without a scenario row, or with
    no replayable step.
    """
    mission_path, out_path = Path(mission_path), Path(out_path)
    logs = [Path(p) for p in log_paths]
    _check_paths(mission_path, logs, out_path)
    mission = load_mission(mission_path)
    runs, start_times, info = [], [], []
    for p in logs:
        run = read_run(p)
        got = run.meta.get("mission")
        if got != mission.name:
            raise LogError(
                f"LOG: {p.name} was flown on mission {got!r}, but {mission_path.name} is mission "
                f"{mission.name!r}; calibrate a mission only with logs of its own runs"
            )
        if _replayable_steps(run, mission.dt) == 0:
            raise LogError(
                f"LOG: {p.name} has no replayable step (no telemetry steps {mission.dt:g} s "
                f"± {MAX_STEP_SHARE:.0%} apart with the set-point flown after them); give logs of runs that flew"
            )
        start_times.append(_start_time(mission, run, p.name))
        runs.append(run)
        info.append(
            {
                "name": p.name,
                "sha256": _sha256(p),
                "scenario": str(run.meta.get("scenario_id", "")),
                "pacing": str(run.meta.get("pacing", "lockstep")),
                "steps": int(run.steps.shape[0]),
            }
        )
    result = fit_vehicle(mission, runs, start_times, fit, bootstrap=bootstrap, seed=seed)
    result.logs = info
    text = mission_path.read_text(encoding="utf-8")
    written = calibrated_text(text, result)
    sidecar = json.dumps(result.to_dict(), indent=2, sort_keys=False, allow_nan=False) + "\n"
    _write_checked(out_path, written, sidecar)
    return result


def _write_checked(out_path: Path, text: str, sidecar: str) -> None:
    """Write the calibrated file (checked to load first) and its sidecar, each atomically."""
    out_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = out_path.with_name(f".{out_path.name}.tmp.toml")
    tmp.write_text(text, encoding="utf-8")
    try:
        load_mission(tmp)
    except InputError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(f"--out: the calibrated file would not load ({exc}); report this as a bug") from None
    os.replace(tmp, out_path)
    side = sidecar_path(out_path)
    tmp_json = side.with_name(f".{side.name}.tmp")
    tmp_json.write_text(sidecar, encoding="utf-8")
    os.replace(tmp_json, side)


# -- writing the calibrated mission file ---------------------------------------------------
def _fmt(v: float) -> str:
    """A TOML float with :data:`DIGITS` significant digits (always a float literal)."""
    r = float(f"{v:.{DIGITS}g}")
    return repr(r) if math.isfinite(r) else "0.0"


_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\" -]+?)\s*\]\]?\s*(#.*)?$")


def calibrated_text(text: str, cal: Calibration) -> str:
    """``text`` (a mission file) with the identified ``[vehicle]`` values set to ``cal``'s and a header comment.

    Only value tokens change: a field's line keeps its comment; a field the file does not
    set is added at the end of ``[vehicle]``'s keys (a ``[vehicle]`` table is appended when
    there is none).
    """
    changes = {n: _fmt(getattr(cal.vehicle, n)) for n in cal.fitted if cal.estimate.identified[n]}
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if (m := _HEADER.match(ln)) and m.group(1) == "vehicle"), None)
    if start is None:
        body = lines + ([""] if lines and lines[-1].strip() else []) + ["[vehicle]"]
        body += [f"{n} = {v}" for n, v in changes.items()]
    else:
        end = next((i for i in range(start + 1, len(lines)) if _HEADER.match(lines[i])), len(lines))
        last_key = start
        done = set()
        for i in range(start + 1, end):
            m = re.match(r"^(\s*)([A-Za-z0-9_]+)(\s*=\s*)([^#]*?)(\s*(#.*)?)$", lines[i])
            if m is None:
                continue
            last_key = i
            if m.group(2) in changes:
                lines[i] = f"{m.group(1)}{m.group(2)}{m.group(3)}{changes[m.group(2)]}{m.group(5)}"
                done.add(m.group(2))
        extra = [f"{n} = {v}" for n, v in changes.items() if n not in done]
        body = lines[: last_key + 1] + extra + lines[last_key + 1 :]
    return "\n".join(_header_comment(cal) + body) + "\n"


def _header_comment(cal: Calibration) -> list[str]:
    est = cal.estimate
    out = [f"# Calibrated by rapt-plan calibrate from {len(cal.logs) or cal.runs} run log(s):"]
    for lg in cal.logs:
        out.append(f"#   {lg['name']}  (scenario {lg['scenario'] or '?'}, sha256 {lg['sha256'][:12]})")
    out.append("# [vehicle] fields fitted (file value -> calibrated +- standard error):")
    for n in cal.fitted:
        old, unit = float(getattr(cal.original, n)), UNITS[n]
        if est.identified[n]:
            new = float(getattr(cal.vehicle, n))
            out.append(f"#   {n:<22} {old:.5g} -> {new:.5g} +- {cal.stderr[n]:.2g} {unit}")
        else:
            out.append(f"#   {n:<22} {old:.5g} {unit} kept: not identified by these logs")
    b, a = cal.rms_before, cal.rms_after
    out.append(
        f"# Segment residual RMS, file vehicle -> calibrated: position {b['position_m']:.3g} -> "
        f"{a['position_m']:.3g} m, heading {b['heading_deg']:.3g} -> {a['heading_deg']:.3g} deg, "
        f"energy {b['energy_wh']:.3g} -> {a['energy_wh']:.3g} Wh"
    )
    out.append("# Everything below is the input mission file; only those [vehicle] values changed.")
    out.append("")
    return out
