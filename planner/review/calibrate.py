"""``rapt-plan calibrate MISSION.toml LOG.mcap... --out F.toml``: the vehicle fit written as a mission file.

The logs are checked and read (:func:`calibrate`), the ``[vehicle]`` block fitted
(:mod:`planner.review.vehicle_fit`), the vehicle's own pack read from its reports
(:mod:`planner.review.pack`), and the day's water added (:mod:`planner.review.daybias`): the
current a calibration run measured, and with ``--bias`` what a comparison established.  A
calibration run's measured speed curve is written as ``[vehicle] speed_curve``.  The output is the input mission file with only the
fitted ``[vehicle]`` values changed (comments and layout kept), a comment block at its top
naming the logs and each fitted value with its standard error, and a JSON sidecar (``--out``
with ``.json``) with the estimates, standard errors, priors and residual RMS before and
after.  Both are deterministic.  Inputs are only read; outputs are written atomically.  Bad
inputs are one-line errors naming the problem.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from planner.review.calibration_legs import (
    cut_legs,
    is_calibration_log,
)
from planner.review.calibration_terms import water_field
from planner.review.day_noise import noise_from_comparison, with_execution_noise
from planner.review.daybias import (
    DayWater,
    header_lines,
    vehicle_compared,
    water_from_comparison,
    water_with_run,
    with_execution_bias,
)
from planner.review.logs import LogError, read_run
from planner.review.pack import PACK_CRITICAL_PERCENT, read_pack
from planner.review.segments import MAX_STEP_SHARE, replayable_steps
from planner.review.vehicle_fit import (
    BOOTSTRAP,
    DIGITS,
    FITTED,
    MIN_LOGS,
    Calibration,
    fit_vehicle,
)
from rapt.errors import InputError
from sim.uuv.mission import Mission
from sim.uuv.missionfile import load_mission
from sim.uuv.scenario import make_scenarios

__all__ = ["calibrate", "calibrated_text", "sidecar_path", "PACK_TOLERANCE"]

#: A pack read within this share of the file's battery is the file's battery (the fit's own spread).
PACK_TOLERANCE = 0.1


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
    if not log_paths:
        _too_few(0)
    if len({p.resolve() for p in log_paths}) < len(log_paths):
        raise InputError("LOGS: a log is given twice; give each run's log once")


def _too_few(n: int) -> None:
    raise InputError(
        f"LOGS: {n} log(s) given; a calibration needs at least {MIN_LOGS} runs (one run's errors cannot be told "
        "from the vehicle's) or a calibration run's log, whose legs are enough alone; give more .mcap logs"
    )


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
    bias: str | Path | None = None,
    keep_unidentified: bool = False,
) -> Calibration:
    """Fit the mission's vehicle block to the logs and write ``out_path`` and its JSON sidecar (module docstring).

    ``bias``, a ``comparison.json`` of ``rapt-plan compare``, adds the day's water it
    established (:func:`planner.review.daybias.water_from_comparison`): the vehicle is then
    fitted in that water and the file gets an ``[execution_bias]`` table beside it, and an ``[execution_noise]``
    table with the execution noise the comparison fitted to the day (:mod:`planner.review.day_noise`), which the
    re-plan then dithers by.

    Refused with a one-line error before anything is written: fewer than :data:`MIN_LOGS`
    logs unless one is a calibration run's (its record lists legs), a log given twice, an ``out_path`` that is not ``.toml`` or would overwrite an
    input, a log that is unreadable, of another mission, without a scenario row, or with
    no replayable step; and, unless ``keep_unidentified``, a fit that leaves a parameter
    unidentified because a calibration leg that would identify it was cut short (the
    watchdog or a pilot took over, or the log ended): it names them (with it, they keep the
    file's values and the header and sidecar say so).
    """
    mission_path, out_path = Path(mission_path), Path(out_path)
    logs = [Path(p) for p in log_paths]
    _check_paths(mission_path, logs, out_path)
    if bias is not None and Path(bias).resolve() in {out_path.resolve(), sidecar_path(out_path).resolve()}:
        raise InputError(f"--out: writing {out_path} would overwrite the --bias input {bias}; choose another file name")
    mission = load_mission(mission_path)
    water, compared = None, None
    if bias is not None:
        water = water_from_comparison(bias, mission)
        compared = vehicle_compared(bias)
        mission = dataclasses.replace(mission, execution_bias=water.bias, execution_bias_source=water.source)
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
    if len(runs) < MIN_LOGS and not any(is_calibration_log(r) for r in runs):
        _too_few(len(runs))
    result = fit_vehicle(mission, runs, start_times, fit, bootstrap=bootstrap, seed=seed, compared=compared)
    result.logs = info
    result.water = _day_water(mission, water, result, [p.name for p, r in zip(logs, runs) if is_calibration_log(r)])
    _limit_battery_to_pack(result, logs)
    result.cut = cut_legs(runs, [p.name for p in logs], mission.dt)
    refused = result.unidentified_by_cut
    if refused and not keep_unidentified:
        cut = sorted({c.describe() for n in refused for c in result.cut_short(n)})
        raise InputError(
            f"LOGS: {', '.join(refused)} not identified because calibration legs were cut short "
            f"({'; '.join(cut)}); nothing written: fly those legs again, or give --keep-unidentified "
            "to keep them at the file's values"
        )
    text = mission_path.read_text(encoding="utf-8")
    written = calibrated_text(text, result)
    if result.water is not None:
        written = with_execution_bias(written, result.water)
    noise = None if bias is None else noise_from_comparison(json.loads(Path(bias).read_text(encoding="utf-8")))
    if noise is not None:  # the re-plan dithers by the noise the day's runs showed
        written = with_execution_noise(written, noise)
    sidecar = json.dumps(result.to_dict(), indent=2, sort_keys=False, allow_nan=False) + "\n"
    _write_checked(out_path, written, sidecar)
    return result


def _day_water(mission: Mission, water: DayWater | None, cal: Calibration, names: list[str]) -> DayWater | None:
    """The water the file gets: compare's (``--bias``) and what the calibration run measured."""
    measured = cal.water_identified
    if not measured:
        return water
    stderr = {water_field(n): cal.stderr[n] for n in measured}
    source = f"rapt-plan calibrate: the calibration run {', '.join(names)}"
    return water_with_run(water, mission.execution_bias, cal.run_water, stderr, source)


def _limit_battery_to_pack(cal: Calibration, logs: Sequence[Path]) -> None:
    """Give the scenario's virtual gauge no more energy than the vehicle's pack holds to the watchdog's limit.

    A scenario's charge is ``start_battery`` of ``battery_wh``; when the vehicle's real pack is
    smaller than that battery (by more than :data:`PACK_TOLERANCE`: a simulated vehicle's pack
    is the file's battery itself), the watchdog surfaces the vehicle before the scenario's
    fuel runs out and the plan predicts ends the vehicle never reaches, so ``battery_wh``
    becomes the pack's energy down to that limit.
    """
    cal.pack = read_pack(logs)
    if cal.pack is not None and cal.pack.capacity_wh < (1.0 - PACK_TOLERANCE) * cal.vehicle.battery_wh:
        cal.vehicle = dataclasses.replace(cal.vehicle, battery_wh=float(_fmt(cal.pack.usable_wh)))
        cal.pack_limits_battery = True


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
    written = [
        n
        for n in cal.fitted
        if cal.estimate.identified[n] and n in FITTED and getattr(cal.vehicle, n) != getattr(cal.original, n)
    ]
    changes = {n: _fmt(getattr(cal.vehicle, n)) for n in written}
    if cal.vehicle.speed_curve != cal.original.speed_curve:
        changes["speed_curve"] = "[" + ", ".join(f"[{_fmt(c)}, {_fmt(r)}]" for c, r in cal.vehicle.speed_curve) + "]"
    if cal.vehicle.velocity_control != cal.original.velocity_control:
        changes["velocity_control"] = f'"{cal.vehicle.velocity_control}"'
    if cal.pack_limits_battery:
        changes["battery_wh"] = _fmt(cal.vehicle.battery_wh)
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
        old, unit = cal.file_value(n), cal.unit(n)
        if est.identified[n]:
            new = cal.value(n)
            out.append(f"#   {n:<22} {old:.5g} -> {new:.5g} +- {cal.stderr[n]:.2g} {unit}")
        else:
            out.append(f"#   {n:<22} {old:.5g} {unit} kept: not identified by these logs")
    for n, need in cal.unidentified.items():
        out.append(f"#   to identify {n}: {need}")
    if cal.control.get("kept"):
        out.append(
            f"#   velocity_control       {cal.control['file']} -> {cal.control['chosen']}: {cal.control['kept']}"
        )
    elif cal.control:
        rms = cal.control["position_rms_m"]
        out.append(
            f"#   velocity_control       {cal.control['file']} -> {cal.control['chosen']}: segment position RMS "
            f"{rms['surge']:.3g} m with a surge loop, {rms['vector']:.3g} m with a vector loop"
        )
    b, a = cal.rms_before, cal.rms_after
    out.append(
        f"# Segment residual RMS, file vehicle -> calibrated: position {b['position_m']:.3g} -> "
        f"{a['position_m']:.3g} m, heading {b['heading_deg']:.3g} -> {a['heading_deg']:.3g} deg, "
        f"energy {b['energy_wh']:.3g} -> {a['energy_wh']:.3g} Wh"
    )
    if cal.pack is not None:
        p = cal.pack
        kept = "" if cal.pack_limits_battery else "; battery_wh kept: the pack is not smaller than it"
        out.append(
            f"# The vehicle's pack: {p.capacity_wh:.4g} Wh ({p.start_percent:.0f}% at the first log's start), "
            f"{p.usable_wh:.4g} Wh when full to the watchdog's {PACK_CRITICAL_PERCENT:g}% limit{kept}"
        )
        if cal.pack_limits_battery:
            out.append(
                f"#   battery_wh {cal.original.battery_wh:.5g} -> {cal.vehicle.battery_wh:.5g} Wh: the pack's usable energy"
            )
    if cal.water is not None:
        out.extend(header_lines(cal.water))
    out.append(
        "# Everything below is the input mission file; only those [vehicle] values changed"
        + (" (battery_wh included)" if cal.pack_limits_battery else "")
        + (" and [execution_bias] was set." if cal.water is not None else ".")
    )
    out.append("")
    return out
