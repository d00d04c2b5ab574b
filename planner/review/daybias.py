"""The day's bias between the morning's logs and the afternoon's plan.

Two directions, both relative to the water a plan was made for:

- :func:`day_bias_record` — what ``rapt-plan compare`` reports beside its fit: the bias the
  plan's mission assumed (its ``[execution_bias]``, :mod:`sim.uuv.missionbias`), and, since
  every prediction composes on top of it, the fitted and the used bias are *residuals*
  relative to it; their totals (:func:`sim.uuv.bias.compose`) are what the water and the
  vehicle did relative to the tide table and the file's vehicle.
- :func:`water_from_comparison` — what ``rapt-plan calibrate --bias comparison.json`` writes
  into the calibrated file's ``[execution_bias]``: the total of the parameters the comparison
  identified *and* whose correction cross-validated, among :data:`WATER_FIELDS`.

``speed`` and ``battery`` are dropped, not folded into the vehicle: the calibration fits
``speed_gain`` and the power terms from the same logs, so they already carry what a speed
or battery bias would (keeping both would count the same effect twice, and folding a speed
bias fitted against the file's vehicle into a calibrated ``speed_gain`` would mix two fits
of one quantity).
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

from rapt.errors import InputError
from sim.uuv.bias import BIAS_NAMES, NEUTRAL, Bias, compose
from sim.uuv.mission import Mission

__all__ = [
    "WATER_FIELDS",
    "DayWater",
    "day_bias_record",
    "water_from_comparison",
    "vehicle_compared",
    "execution_bias_table",
    "with_execution_bias",
    "with_table",
    "header_lines",
    "water_record",
    "water_with_run",
]

#: The bias fields a calibrated file carries: the water (tide scale, a steady current along and
#: across the flood, the tide's clock) and the crab angle no [vehicle] field describes.
WATER_FIELDS: tuple[str, ...] = ("current_scale", "current_offset", "current_cross", "start_time", "heading")


def day_bias_record(mission: Mission, fitted: Bias, used: Bias) -> dict:
    """``comparison.json``'s ``day_bias``: the plan's assumed bias and the totals of the fitted and used ones."""
    assumed = mission.execution_bias
    return {
        "assumed": assumed.to_dict(),
        "source": mission.execution_bias_source,
        "relative": not assumed.is_neutral,
        "fitted_total": compose(assumed, fitted).to_dict(),
        "correction_total": compose(assumed, used).to_dict(),
        "note": (
            "the plan was made for this day's bias; bias and correction.bias are relative to it "
            "(scales multiply, offsets add), the totals relative to the tide table and the file's vehicle"
            if not assumed.is_neutral
            else "the plan assumed the tide table and the file's vehicle; the totals equal the fitted bias"
        ),
    }


class DayWater:
    """The water a comparison established, ready for a calibrated file's ``[execution_bias]``."""

    def __init__(
        self,
        bias: Bias,
        fields: dict[str, dict],
        source: str,
        dropped: dict[str, str],
        rule: str = "identified, cross-validated",
    ):
        self.bias = bias  # total: relative to the tide table; fields not taken are neutral
        self.fields = fields  # name -> {"value", "stderr"} of each field taken
        self.source = source
        self.dropped = dropped  # name -> why it was not taken
        self.rule = rule  # what a field needed to be taken


def _read(path: Path) -> dict:
    try:
        raw = path.read_bytes()
        data = json.loads(raw)
    except OSError as exc:
        raise InputError(
            f"--bias: cannot read {path} ({exc.strerror or exc}); give compare's comparison.json"
        ) from None
    except ValueError:
        raise InputError(f"--bias: {path} is not JSON; give the comparison.json rapt-plan compare wrote") from None
    if not isinstance(data, dict) or not str(data.get("schema", "")).startswith("rapt.comparison/"):
        raise InputError(
            f"--bias: {path} is not a comparison (no rapt.comparison schema); give compare's comparison.json"
        )
    for key in ("plan", "bias", "correction"):
        if not isinstance(data.get(key), dict):
            raise InputError(f"--bias: {path} has no {key!r} record; give a comparison.json of this version")
    data["_sha256"] = hashlib.sha256(raw).hexdigest()
    return data


def vehicle_compared(path: str | Path) -> dict | None:
    """The calibrated vehicle's fields the comparison ``path`` predicted with (None: it used none).

    Its speed loop was chosen, and its turn found, on the calibration run; a calibration that adds the
    day's water to the same vehicle keeps the loop and starts the turn there rather than searching both
    again, which is most of a calibration's time.
    """
    vehicle = _read(Path(path)).get("calibrated_vehicle")
    return vehicle if isinstance(vehicle, dict) else None


def water_from_comparison(path: str | Path, mission: Mission) -> DayWater:
    """The identified, cross-validated water of ``path`` (a ``comparison.json``) as a total bias.

    One-line InputError when the file is not a comparison or is one of another mission.
    When the comparison's correction did not cross-validate nothing is taken (every field
    neutral, each dropped with the reason).
    """
    path = Path(path)
    data = _read(path)
    got = data["plan"].get("mission")
    if got != mission.name:
        raise InputError(
            f"--bias: {path} compares runs of mission {got!r}, but the mission file is {mission.name!r}; "
            "give the comparison of this mission's runs"
        )
    used = data["correction"].get("used") is True
    fit = data["bias"]
    day = data.get("day_bias") or {}
    assumed = Bias(**{n: float(day.get("assumed", NEUTRAL).get(n, NEUTRAL[n])) for n in BIAS_NAMES})
    residual = {n: NEUTRAL[n] for n in BIAS_NAMES}
    fields, dropped = {}, {}
    for n in BIAS_NAMES:
        rec = fit.get(n) or {}
        if n not in WATER_FIELDS:
            dropped[n] = "carried by the calibrated vehicle (speed_gain, power terms)"
        elif not used:
            dropped[n] = "the comparison's correction did not cross-validate"
        elif not rec.get("identified"):
            dropped[n] = "not identified by the comparison's logs"
        else:
            residual[n] = float(rec["estimate"])
            fields[n] = {"stderr": float(rec.get("stderr", 0.0))}
    total = compose(assumed, Bias(**residual))
    water = {n: (getattr(total, n) if n in WATER_FIELDS else NEUTRAL[n]) for n in BIAS_NAMES}
    for n in fields:
        fields[n]["value"] = water[n]
    plan = data["plan"].get("id", "?")
    source = f"rapt-plan compare of plan {plan} ({path.name} sha256 {data['_sha256'][:12]})"
    return DayWater(_day_bias(water), fields, source, dropped)


def water_with_run(
    water: DayWater | None, assumed: Bias, run_water: Bias, stderr: dict[str, float], source: str
) -> DayWater:
    """The day's water with what a calibration run measured in it: ``run_water`` (relative to
    ``assumed``, the water the fit flew: the file's table or ``water``'s) composed onto it, the
    fields in ``stderr`` taken with those standard errors.  ``water`` (compare's, or None)
    keeps every other field it took."""
    total = compose(assumed, run_water)
    fields = dict(water.fields) if water is not None else {}
    unmeasured = {n: "not measured by the calibration run" for n in WATER_FIELDS}
    dropped = dict(water.dropped) if water is not None else unmeasured
    for n, se in stderr.items():
        fields[n] = {"value": round(float(getattr(total, n)), 6), "stderr": float(se)}
        dropped.pop(n, None)
    values = {n: (round(getattr(total, n), 6) if n in WATER_FIELDS else NEUTRAL[n]) for n in BIAS_NAMES}
    both = source if water is None else f"{source}; {water.source}"
    rule = "identified by the calibration run" + ("" if water is None else f"; compare's: {water.rule}")
    return DayWater(_day_bias(values), fields, both, dropped, rule)


def _day_bias(values: dict[str, float]) -> Bias:
    """A :class:`Bias` of ``values``; InputError when a total left the range a mission file accepts."""
    try:
        return Bias(**values)
    except InputError as exc:
        raise InputError(f"--bias: the day's total bias cannot be written to a mission file ({exc})") from None


def _fmt(v: float) -> str:
    return repr(float(f"{v:.6g}"))


def execution_bias_table(water: DayWater) -> list[str]:
    """The ``[execution_bias]`` table's lines for ``water`` (each field, its s.e. as a comment, the source)."""
    lines = ["[execution_bias]"]
    for n in WATER_FIELDS:
        v = getattr(water.bias, n)
        if n in water.fields:
            why = f"  # +- {water.fields[n]['stderr']:.2g} (fitted)"
        else:
            kept = "as the plan assumed" if v != NEUTRAL[n] else "neutral"
            why = f"  # {kept}: {water.dropped.get(n, 'not fitted')}"
        lines.append(f"{n} = {_fmt(v)}{why}")
    lines.append(f"source = {json.dumps(water.source)}")
    return lines


_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_.\" -]+?)\s*\]\]?\s*(#.*)?$")


def with_execution_bias(text: str, water: DayWater) -> str:
    """Mission-file ``text`` with its ``[execution_bias]`` table (if any) replaced by ``water``'s, at the end."""
    return with_table(text, "execution_bias", execution_bias_table(water))


def with_table(text: str, section: str, table: list[str]) -> str:
    """Mission-file ``text`` with its ``[section]`` table (if any) replaced by the lines ``table``, at the end."""
    lines = text.splitlines()
    start = next((i for i, ln in enumerate(lines) if (m := _HEADER.match(ln)) and m.group(1) == section), None)
    if start is not None:
        end = next((i for i in range(start + 1, len(lines)) if _HEADER.match(lines[i])), len(lines))
        lines = lines[:start] + lines[end:]
    while lines and not lines[-1].strip():
        lines.pop()
    return "\n".join([*lines, "", *table]) + "\n"


def header_lines(water: DayWater) -> list[str]:
    """Comment lines for the calibrated file's header: which water it now carries and why."""
    taken = ", ".join(f"{n} {v['value']:.5g} +- {v['stderr']:.2g}" for n, v in water.fields.items()) or "none"
    return [
        f"# [execution_bias] the day's water from {water.source}:",
        f"#   taken ({water.rule}): {taken}",
        "#   the [vehicle] fit above was made in that water",
    ]


def water_record(water: DayWater) -> dict:
    """The calibration sidecar's ``execution_bias`` record."""
    return {
        "bias": water.bias.to_dict(),
        "fields": water.fields,
        "dropped": water.dropped,
        "source": water.source,
    }
