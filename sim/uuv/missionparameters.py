"""The [[parameters]] of a mission file: the state space and what each parameter sets.

Each entry becomes a :mod:`rapt.space` parameter (file order) and a
:class:`sim.uuv.mission.Binding` to the mission field its ``target`` names; the target must
exist in the file and the parameter's range must fit what the field can hold (positions
inside the operational area, times and fractions within theirs).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from rapt.space import Categorical, Continuous, Integer, Parameter, Permutation, StateSpace
from sim.uuv.mission import FIELD_RESOLUTION, TARGET_FIELDS, Binding, Rect, Transmission
from sim.uuv.missionfields import FieldChecker, fmt, names

__all__ = ["ParameterReader"]

_PARAM_KINDS = ("continuous", "integer", "categorical", "permutation")
_PARAM_KEYS = {
    "continuous": (("name", "kind", "target", "low", "high"), ("log", "resolution")),
    "integer": (("name", "kind", "target", "low", "high"), ()),
    "categorical": (("name", "kind", "target", "choices"), ()),
    "permutation": (("name", "kind", "target", "items"), ()),
}
#: Target kinds written without an element name.
_UNNAMED_TARGETS = ("mission", "vehicle", "mission_areas", "transmission")
#: Target kind -> (file section, words for its elements).
_NAMED_TARGETS = {
    "nogo": ("nogo", "no-go areas"),
    "barrier": ("barriers", "barriers"),
    "obstacle": ("obstacles", "obstacles"),
    "mission_area": ("mission_areas", "mission areas"),
}


class ParameterReader(FieldChecker):
    """Reads [[parameters]] of the file ``label`` against its operational area ``op``, the named
    ``elements`` per target kind and its ``transmission`` (None when the file has none)."""

    def __init__(self, label: str, op: Rect, elements: dict[str, list[str]], transmission: Transmission | None):
        super().__init__(label)
        self.op, self.elements, self.transmission = op, elements, transmission

    def read(self, specs: list[dict], area_names: list[str]) -> tuple[StateSpace, tuple[Binding, ...]]:
        if not specs:
            self.fail("parameters", "no [[parameters]] entries; a study needs at least one parameter")
        params: list[Parameter] = []
        bindings: list[Binding] = []
        seen_names: dict[str, str] = {}
        seen_targets: dict[tuple, str] = {}
        for i, p in enumerate(specs):
            where = f"parameters[{i}]"
            kind = self.string(p, "kind", where)
            if kind not in _PARAM_KINDS:
                self.fail(f"{where}.kind", f"unknown kind {kind!r}; allowed: {names(_PARAM_KINDS)}")
            if p.get("target") == "mission_areas.priority" and kind != "permutation":
                self.fail(
                    f"{where}.kind",
                    f'kind {kind!r} cannot set mission_areas.priority; use kind = "permutation" '
                    "with items = the mission-area names",
                )
            required, optional = _PARAM_KEYS[kind]
            self.keys(p, where, required, optional)
            pname = self.string(p, "name", where)
            if pname in seen_names:
                self.fail(
                    f"{where}.name",
                    f"duplicate parameter name {pname!r} (also {seen_names[pname]}); give every parameter its own name",
                )
            seen_names[pname] = where
            binding = self.target(p, where, pname)
            key = (binding.kind, binding.name, binding.field)
            if key in seen_targets:
                self.fail(
                    f"{where}.target",
                    f"{p['target']!r} is already set by {seen_targets[key]}; give each field one parameter",
                )
            seen_targets[key] = where
            if binding.field == "priority":
                params.append(self.priority_parameter(p, where, pname, area_names))
            elif kind == "permutation":
                self.fail(
                    f"{where}.kind",
                    f"a permutation can only target mission_areas.priority, not {p['target']!r}; "
                    "use continuous, integer or categorical",
                )
            elif kind == "categorical":
                params.append(self.categorical_parameter(p, where, pname, binding))
            else:
                params.append(self.numeric_parameter(p, where, kind, pname, binding))
            bindings.append(binding)
        try:
            space = StateSpace(params)
        except ValueError as exc:  # pragma: no cover - everything is checked above
            self.fail("parameters", str(exc))
        return space, tuple(bindings)

    def priority_parameter(self, p: Mapping, where: str, pname: str, area_names: list[str]) -> Permutation:
        """A permutation of the mission areas' priority order: every area named exactly once."""
        tfield = f"{where}.target"
        items = self.string_list(p["items"], f"{where}.items")
        if sorted(items) != sorted(area_names) or len(set(items)) != len(items):
            self.fail(
                f"{where}.items",
                f"{items!r} is not the mission-area names; list each of {names(area_names)} exactly once",
            )
        if len(items) < 2:
            self.fail(
                f"{tfield}",
                "a priority permutation needs at least 2 mission areas; drop this parameter or add [[mission_areas]]",
            )
        return Permutation(pname, tuple(items))

    def categorical_parameter(self, p: Mapping, where: str, pname: str, binding: Binding) -> Categorical:
        """A choice among at least two distinct numbers, each within the target field's range."""
        choices = p["choices"]
        if not isinstance(choices, list):
            self.fail(
                f"{where}.choices",
                f"expected a list of numbers, got {choices!r}; write e.g. choices = [0.1, 0.2]",
            )
        values = [self.check_number(c, f"{where}.choices[{j}]") for j, c in enumerate(choices)]
        if len(values) < 2 or len(set(values)) != len(values):
            self.fail(f"{where}.choices", f"{choices!r} needs at least 2 distinct values; add or de-duplicate choices")
        self.value_range(binding, min(values), max(values), f"{where}.choices")
        return Categorical(pname, tuple(values))

    def numeric_parameter(
        self, p: Mapping, where: str, kind: str, pname: str, binding: Binding
    ) -> Integer | Continuous:
        """An integer or continuous range (optionally log-scaled) within the target field's range."""
        if kind == "integer":
            for k in ("low", "high"):
                if isinstance(p[k], bool) or not isinstance(p[k], int):
                    self.fail(
                        f"{where}.{k}",
                        f"an integer parameter needs whole-number bounds, got {p[k]!r}; "
                        'write e.g. 3, or use kind = "continuous"',
                    )
        low = self.check_number(p["low"], f"{where}.low")
        high = self.check_number(p["high"], f"{where}.high")
        if low >= high:
            self.fail(f"{where}.low", f"low={fmt(low)} must be < high={fmt(high)}; swap or widen the bounds")
        log = False
        if "log" in p:
            log = p["log"]
            if not isinstance(log, bool):
                self.fail(f"{where}.log", f"expected true or false, got {log!r}")
            if log and low <= 0:
                self.fail(f"{where}.low", f"log scale needs low > 0, got {fmt(low)}; raise low or set log = false")
        self.value_range(binding, low, high, where)
        if kind == "integer":
            return Integer(pname, int(low), int(high))
        return Continuous(pname, low, high, log, self.resolution(p, where, binding, low, high))

    def resolution(self, p: Mapping, where: str, binding: Binding, low: float, high: float) -> float:
        """The step the parameter's values snap to: the file's ``resolution``, else its field's (FIELD_RESOLUTION)."""
        if "resolution" not in p:
            return min(FIELD_RESOLUTION[binding.field], (high - low) / 2)
        step = self.check_number(p["resolution"], f"{where}.resolution")
        if not 0 < step <= (high - low) / 2:
            self.fail(
                f"{where}.resolution",
                f"expected a step in (0, {fmt((high - low) / 2)}] (at least three settable values), got {fmt(step)}; "
                "give the finest step the range can set this value to",
            )
        return step

    def target(self, p: Mapping, where: str, pname: str) -> Binding:
        field = f"{where}.target"
        target = self.string(p, "target", where)
        parts = target.split(".")
        kinds = tuple(TARGET_FIELDS)
        kind = parts[0]
        if kind not in TARGET_FIELDS or not 2 <= len(parts) <= 3 or not all(parts):
            self.fail(
                field,
                f"{target!r} is not a target; write '<kind>.<field>' or '<kind>.<element name>.<field>' "
                f"with kind one of {names(kinds)}",
            )
        if kind in _UNNAMED_TARGETS:
            if len(parts) == 3:
                self.fail(field, f"{kind!r} takes no element name; write '{kind}.{parts[2]}'")
            name, attr = None, parts[1]
            if kind == "transmission" and self.transmission is None:
                self.fail(
                    field,
                    f"{target!r} targets the transmission area but the file has no [transmission]; "
                    "add [transmission] or drop this parameter",
                )
            if kind == "mission_areas" and not self.elements["mission_area"]:
                self.fail(field, f"{target!r} but the file has no [[mission_areas]]; add them or drop this parameter")
        else:
            section, words = _NAMED_TARGETS[kind]
            known = self.elements[kind]
            if len(parts) == 2:
                example = known[0] if known else "<name>"
                self.fail(
                    field,
                    f"{kind!r} needs an element name; write '{kind}.{example}.{parts[1]}' "
                    f"(known {words}: {names(known)})",
                )
            name, attr = parts[1], parts[2]
            if name not in known:
                self.fail(
                    field,
                    f"unknown element '{kind}.{name}' (known {words}: {names(known)}); "
                    f"name an element defined in [[{section}]]",
                )
        if attr not in TARGET_FIELDS[kind]:
            self.fail(field, f"{kind!r} has no settable field {attr!r}; settable: {names(TARGET_FIELDS[kind])}")
        return Binding(pname, kind, name, attr)

    def value_range(self, b: Binding, low: float, high: float, where: str) -> None:
        """Check a parameter's range against what its field can hold (``where`` is the entry or its choices)."""
        field = b.field
        bound = where if where.endswith(".choices") else None
        if field in ("x", "y"):
            op = self.op
            c, size = (op.x, op.width) if field == "x" else (op.y, op.height)
            lo, hi = c - size / 2, c + size / 2
            if low < lo or high > hi:
                self.fail(
                    bound or f"{where}.{'low' if low < lo else 'high'}",
                    f"{field} range {fmt(low)}..{fmt(high)} leaves the operational area "
                    f"({field} {fmt(lo)}..{fmt(hi)}); keep positions inside it",
                )
            return
        limits = {
            "start_time_s": (0.0, 86400.0, "seconds after local midnight"),
            "start_battery": (0.0, 1.0, "a fraction of the battery"),
            "window_start_s": (0.0, math.inf, "seconds after the mission start"),
            "window_length_s": (0.0, math.inf, "a duration in seconds"),
            "dwell_s": (0.0, math.inf, "a duration in seconds"),
        }
        if field in limits:
            lo, hi, what = limits[field]
            if low < lo or high > hi:
                self.fail(
                    bound or f"{where}.{'low' if low < lo else 'high'}",
                    f"{b.kind}.{field} is {what}; keep the range {fmt(low)}..{fmt(high)} within {fmt(lo)}..{fmt(hi)}",
                )
