"""Checks every mission-file reader shares: typed fields, known keys, one-line errors.

Each section reader of a mission file (:mod:`sim.uuv.missionfile`, :mod:`sim.uuv.missionparameters`,
:mod:`sim.uuv.missionscoretree`) is a :class:`FieldChecker` for the file it reads, so every
problem is reported the same way: a :class:`MissionFileError` of one line naming the file,
the field, the problem and the fix.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping
from typing import Any, NoReturn

from rapt.errors import FileFormatError

__all__ = ["MISSING", "FieldChecker", "MissionFileError", "fmt", "names"]


class MissionFileError(FileFormatError):
    """A mission file that cannot be loaded; the message is one line: file, field, problem, fix.

    A :class:`rapt.errors.FileFormatError`, so also an ``InputError``, a ``RaptError`` and a ``ValueError``.
    """


#: Default of a required field: no default.
MISSING = object()


def fmt(v: float) -> str:
    return f"{v:g}"


def names(items) -> str:
    items = list(items)
    return ", ".join(map(str, items)) if items else "none"


class FieldChecker:
    """Reads typed fields of the mission file ``label``; :meth:`fail` raises its one-line error."""

    def __init__(self, label: str):
        self.label = label

    def fail(self, where: str, message: str) -> NoReturn:
        message = " ".join(str(message).split())  # one line, always
        raise MissionFileError(f"{self.label}: {where}: {message}")

    def table(self, value: Any, where: str, header: str) -> dict:
        if not isinstance(value, dict):
            self.fail(where, f"expected a table, got {type(value).__name__} {value!r}; write it as {header}")
        return value

    def keys(self, tbl: Mapping, where: str, required=(), optional=()) -> None:
        allowed = tuple(required) + tuple(optional)
        for key in tbl:
            if key not in allowed:
                hint = difflib.get_close_matches(key, allowed, n=1)
                did = f" (did you mean '{hint[0]}'?)" if hint else ""
                self.fail(f"{where}.{key}" if where else key, f"unknown key{did}; allowed keys: {names(allowed)}")
        for key in required:
            if key not in tbl:
                self.fail(
                    f"{where}.{key}" if where else key,
                    f"missing required key; add {key} = ... to {where or 'the file'}",
                )

    def number(
        self,
        tbl: Mapping,
        key: str,
        where: str,
        default: Any = MISSING,
        *,
        low: float | None = None,
        high: float | None = None,
        positive: bool = False,
    ) -> float:
        field = f"{where}.{key}"
        if key not in tbl:
            if default is MISSING:
                self.fail(field, f"missing required number; add {key} = <number> to {where}")
            return default
        return self.check_number(tbl[key], field, low=low, high=high, positive=positive)

    def check_number(
        self, v: Any, field: str, *, low: float | None = None, high: float | None = None, positive: bool = False
    ) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(field, f"expected a number, got {type(v).__name__} {v!r}; write a plain number such as 10.0")
        v = float(v)
        if not math.isfinite(v):
            self.fail(field, f"{v} is not finite; give a finite number")
        if positive and v <= 0:
            self.fail(field, f"{fmt(v)} must be > 0; give a positive number")
        if low is not None and v < low:
            self.fail(
                field,
                f"{fmt(v)} is below the minimum {fmt(low)}; use a value in [{fmt(low)}, {fmt(high) if high is not None else 'inf'}]",
            )
        if high is not None and v > high:
            self.fail(
                field,
                f"{fmt(v)} is above the maximum {fmt(high)}; use a value in [{fmt(low) if low is not None else '-inf'}, {fmt(high)}]",
            )
        return v

    def string(self, tbl: Mapping, key: str, where: str, default: Any = MISSING) -> str:
        field = f"{where}.{key}"
        if key not in tbl:
            if default is MISSING:
                self.fail(field, f'missing required string; add {key} = "..." to {where}')
            return default
        v = tbl[key]
        if not isinstance(v, str) or not v:
            self.fail(field, f'expected a non-empty string, got {v!r}; write {key} = "..."')
        return v

    def string_list(self, v: Any, field: str) -> list[str]:
        if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
            self.fail(field, f'expected a list of strings, got {v!r}; write e.g. ["A", "B"]')
        return v

    def array(self, data: Mapping, key: str) -> list[dict]:
        v = data.get(key, [])
        if not isinstance(v, list):
            self.fail(key, f"expected an array of tables, got {type(v).__name__}; write each entry as [[{key}]]")
        for i, item in enumerate(v):
            self.table(item, f"{key}[{i}]", f"[[{key}]]")
        return v
