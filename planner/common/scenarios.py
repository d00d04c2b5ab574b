"""Naming a scenario on the command line: a number or a file.

A number picks that row of the mission's scenario design (a scrambled Sobol sequence,
seed 0, so the same number is the same scenario on every machine); without one, the
commands take the design's first valid row (row 0 of a mission may well be invalid, e.g.
a no-go area on a mission area).  A file is JSON with
either ``"u"`` (a unit-cube row, as a study stores it) or ``"parameters"`` (physical
values by parameter name, as a field plan lists them).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from scipy.stats import qmc

from rapt.errors import FileFormatError, InputError
from sim.uuv.mission import Mission

__all__ = ["resolve_scenario", "design_row", "valid_design_rows"]

SEARCHED_ROWS = 1024  # design rows looked through for valid ones


def design_row(mission: Mission, index: int) -> np.ndarray:
    """Row ``index`` of the mission's Sobol design (seed 0)."""
    if index < 0:
        raise InputError(f"--scenario: expected a row number >= 0, got {index}")
    sobol = qmc.Sobol(mission.dim, scramble=True, seed=0)
    if index:
        sobol.fast_forward(index)
    return sobol.random(1)[0]


def valid_design_rows(mission: Mission, count: int = 3) -> list[int]:
    """The first ``count`` row numbers of the mission's design that are valid scenarios (fewer if the
    first :data:`SEARCHED_ROWS` rows hold fewer)."""
    from sim.uuv.scenario import make_scenarios

    U = qmc.Sobol(mission.dim, scramble=True, seed=0).random(SEARCHED_ROWS)
    return [int(i) for i in np.flatnonzero(make_scenarios(mission, U).valid)[:count]]


def resolve_scenario(mission: Mission, spec: str) -> tuple[np.ndarray, str]:
    """(unit-cube row, scenario id) for ``--scenario`` given as a number or a JSON file."""
    if spec.strip().isdigit():
        return design_row(mission, int(spec)), f"sobol-{int(spec)}"
    path = Path(spec)
    if not path.is_file():
        raise InputError(f"--scenario: {spec!r} is neither a row number nor an existing JSON file")
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise FileFormatError(f"--scenario: {path} is not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(data, dict) and "u" in data:
        u = np.asarray(data["u"], dtype=float)
        if u.shape != (mission.dim,) or np.any(u < 0) or np.any(u > 1):
            raise FileFormatError(f"--scenario: {path}: 'u' must be {mission.dim} numbers in [0, 1]")
    elif isinstance(data, dict) and "parameters" in data:
        names = set(mission.space.names)
        given = data["parameters"]
        missing = sorted(names - set(given))
        if missing:
            raise FileFormatError(f"--scenario: {path}: parameters lack {', '.join(missing)}; give every parameter")
        u = mission.space.encode([given])[0]
    else:
        raise FileFormatError(f"--scenario: {path}: expected a JSON object with 'u' or 'parameters'")
    return u, str(data.get("id", path.stem))
