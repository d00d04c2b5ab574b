"""The ``[execution_bias]`` table of a mission file: the day's water and vehicle, as the logs showed them.

The mission file's ``[current]`` and ``[vehicle]`` describe the tide table and vehicle the
back-seat autonomy plans with.  On a range day the water and the vehicle depart from them
the same way run after run (:mod:`sim.uuv.bias`): the firmware feels no tide while the
table says 1 m/s, the tidal file runs an hour late.  Once a morning's logs have measured
that (``rapt-plan compare``, then ``rapt-plan calibrate --bias``), the afternoon's plan
must be made for that water, not the table's.  The table says so:

.. code-block:: toml

    [execution_bias]              # optional; every key optional, neutral by default
    current_scale = 0.34          # true tidal current / the tide table's          (x, 0..3)
    current_offset = 0.0          # m/s added along [current] direction_deg        (-2..2)
    current_cross = 0.0           # m/s added towards direction_deg + 90           (-2..2)
    start_time = 0.0              # s the true tide runs ahead of the table        (-43200..43200)
    heading = 0.0                 # deg the track runs clockwise of the bow        (-45..45)
    speed = 1.0                   # through-water speed per commanded              (x, 0.5..2)
    battery = 1.0                 # energy delivered per unit of gauge charge      (x, 0.25..4)
    source = "compare of plan 1a2b3c, logs ..."   # free text: where the values came from

Every simulation of the mission (:func:`sim.uuv.simulate`, the world of the MAVLink
front-seat, the segment replay of the bias and vehicle fits) flies that bias while the
autonomy keeps planning with the table and the file's vehicle, and composes any bias it
is given on top of it (:func:`sim.uuv.bias.compose`): a bias fitted to logs of a plan made
for this water is relative to it.  Without the table, or with every value neutral, the
mission runs bit for bit as before.
"""

from __future__ import annotations

from collections.abc import Mapping

from sim.uuv.bias import BIAS_LIMITS, BIAS_NAMES, NEUTRAL, Bias
from sim.uuv.missionfields import FieldChecker

__all__ = ["SECTION", "read_execution_bias"]

#: The table's name in a mission file.
SECTION = "execution_bias"


def read_execution_bias(checker: FieldChecker, data: Mapping) -> tuple[Bias, str | None]:
    """The day's bias and its source from the parsed file ``data`` (neutral and None without the table).

    Problems are ``checker``'s one-line errors naming ``execution_bias.<key>``.
    """
    if SECTION not in data:
        return Bias(), None
    tbl = checker.table(data[SECTION], SECTION, f"[{SECTION}]")
    checker.keys(tbl, SECTION, (), (*BIAS_NAMES, "source"))
    values = {}
    for name in BIAS_NAMES:
        lo, hi = BIAS_LIMITS[name]
        values[name] = checker.number(tbl, name, SECTION, NEUTRAL[name], low=lo, high=hi)
    source = checker.string(tbl, "source", SECTION, "")
    return Bias(**values), source
