"""The ``[execution_noise]`` table of a mission file: how far the day's runs strayed from the model.

A plan dithers its scenarios by an expected execution noise: navigation error on positions,
start and timing slip on times, gauge error on the starting charge. A morning's logs measure
that noise for the vehicle in its water (``rapt-plan compare`` fits it; ``rapt-plan calibrate
--bias`` writes it here), and the afternoon's re-plan must dither by what the day showed, not
by an assumption. The table says so:

.. code-block:: toml

    [execution_noise]             # optional; the sigmas the re-plan dithers by
    position = 4.2                # m, navigation error on every position        (> 0)
    time = 12.0                   # s, start and timing slip on every time       (> 0)
    battery = 0.4                 # % of capacity, gauge error on the charge     (> 0)
    source = "compare of plan 1a2b3c: 6 runs"   # free text: where the values came from

The simulator itself never reads it: it changes no run, only the noise a plan assumes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from sim.uuv.missionfields import FieldChecker

__all__ = ["SECTION", "ExecutionNoise", "read_execution_noise", "execution_noise_table"]

#: The table's name in a mission file.
SECTION = "execution_noise"
_KINDS = ("position", "time", "battery")


@dataclass(frozen=True)
class ExecutionNoise:
    """The day's execution noise: sigmas in metres, seconds and percent of capacity, and where they came from."""

    position: float
    time: float
    battery: float
    source: str = ""

    def spec(self) -> str:
        """As ``--dither-sigma`` writes it."""
        return f"position={self.position:.6g},time={self.time:.6g},battery={self.battery:.6g}"


def read_execution_noise(checker: FieldChecker, data: Mapping) -> ExecutionNoise | None:
    """The table from the parsed file ``data`` (None without it); one-line errors name ``execution_noise.<key>``."""
    if SECTION not in data:
        return None
    tbl = checker.table(data[SECTION], SECTION, f"[{SECTION}]")
    checker.keys(tbl, SECTION, _KINDS, ("source",))
    values = {kind: checker.number(tbl, kind, SECTION, positive=True) for kind in _KINDS}
    return ExecutionNoise(**values, source=checker.string(tbl, "source", SECTION, ""))


def execution_noise_table(noise: ExecutionNoise) -> list[str]:
    """The table's lines, as a mission file holds them."""
    source = noise.source.replace("\\", "\\\\").replace('"', '\\"')
    return [
        f"[{SECTION}]",
        f"position = {noise.position:.6g}  # m",
        f"time = {noise.time:.6g}  # s",
        f"battery = {noise.battery:.6g}  # % of capacity",
        f'source = "{source}"',
    ]
