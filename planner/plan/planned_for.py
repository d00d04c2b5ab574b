"""What vehicle and what water a plan was made for: ``plan.json``'s ``mission.planned_for``.

A re-plan made from a calibrated mission file (``rapt-plan calibrate``) with the day's
execution bias (``[execution_bias]``, :mod:`sim.uuv.missionbias`) predicts every outcome
for that vehicle in that water; whoever flies it, and ``rapt-plan compare`` afterwards,
must know which.  :func:`planned_for` records it when the mission file says something
about the day (an ``[execution_bias]`` table, or the header ``rapt-plan calibrate``
writes): the vehicle (its values, and the calibration's own account of the logs it came
from and each fitted value), the water (the tide table and the day's bias, where the
bias came from).  A mission file that says neither records nothing, so plans of such
files are what they were before this record existed, byte for byte.
"""

from __future__ import annotations

import dataclasses

from planner.common.jsonio import jsonable
from sim.uuv.bias import BIAS_UNITS, NEUTRAL
from sim.uuv.mission import Mission

__all__ = ["CALIBRATED_MARK", "planned_for", "summary_lines"]

#: How the header of a file written by ``rapt-plan calibrate`` begins
#: (:func:`planner.review.calibrate.calibrated_text`; the plan stage does not import the review stage).
CALIBRATED_MARK = "# Calibrated by rapt-plan calibrate"
_HEADER_END = "# Everything below is the input mission file"


def calibration_header(text: str) -> list[str]:
    """The comment lines ``rapt-plan calibrate`` put at the top of ``text`` (none when it did not write it)."""
    lines = text.splitlines()
    if not lines or not lines[0].startswith(CALIBRATED_MARK):
        return []
    out = []
    for ln in lines:
        if not ln.startswith("#"):
            break
        out.append(ln[1:].strip())
        if ln.startswith(_HEADER_END):
            break
    return out


def planned_for(mission: Mission, text: str, sha256: str) -> dict | None:
    """The ``planned_for`` record of ``mission`` (file ``text`` with digest ``sha256``), None when
    the file has neither an ``[execution_bias]`` table nor a calibration header."""
    calibration = calibration_header(text)
    has_table = mission.execution_bias_source is not None
    if not calibration and not has_table:
        return None
    b = mission.execution_bias
    return {
        "mission_sha256": sha256,
        "vehicle": {
            "calibrated": bool(calibration),
            "calibration": calibration,
            "values": jsonable(dataclasses.asdict(mission.vehicle)),
        },
        "water": {
            "tide_table": jsonable(dataclasses.asdict(mission.current)),
            "execution_bias": b.to_dict(),
            "units": dict(BIAS_UNITS),
            "neutral": b.is_neutral,
            "source": mission.execution_bias_source if has_table else None,
        },
    }


def _speed(values: dict) -> str:
    """The vehicle's speed answer: its measured curve's knots, else its speed gain."""
    curve = values.get("speed_curve") or []
    if curve:
        return "speed " + ", ".join(f"{c:.3g}->{r:.3g}" for c, r in curve) + " m/s"
    return f"speed_gain {values['speed_gain']:.4g}"


def _surface(values: dict) -> str:
    """The vehicle's surface terms, when it has any."""
    cap, extra = values.get("surface_max_speed") or 0.0, values.get("surface_power_w") or 0.0
    if not cap and not extra:
        return ""
    return ", at the surface" + (f" at most {cap:.3g} m/s" if cap else "") + (f" {extra:+.4g} W" if extra else "")


def summary_lines(record: dict | None) -> list[str]:
    """One line for the vehicle and one for the water, for the terminal summary and the report."""
    if not record:
        return []
    veh, water = record["vehicle"], record["water"]
    v = veh["values"]
    vehicle = (
        "calibrated vehicle" if veh["calibrated"] else "the mission file's vehicle"
    ) + f" ({_speed(v)}, hotel {v['hotel_w']:.4g} W, drag {v['drag_w']:.4g} W{_surface(v)})"
    if veh["calibrated"] and len(veh["calibration"]) > 1:
        vehicle += f"; {veh['calibration'][0].rstrip(':')}"
    changed = [
        f"{n} {val:g}{'' if water['units'][n] == 'x' else ' ' + water['units'][n]}"
        for n, val in water["execution_bias"].items()
        if val != NEUTRAL[n]
    ]
    bias = ", ".join(changed) if changed else "none (the tide table as written)"
    source = f" — from {water['source']}" if water.get("source") else ""
    return [f"planned for: {vehicle}", f"water: day's bias {bias}{source}"]
