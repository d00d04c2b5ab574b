"""Runs as a log holds them, straight from the batch simulator: fast inputs for the fits.

Lock-step SIL is bit-exact with the batch simulator (tests/planner/fly/sil/test_loop.py), so a
batch trajectory carries what :func:`planner.review.logs.read_run` returns for a logged run:
the reported steps and the set-point flown after each.  The slow tests fly real logs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import sim.uuv
from planner.review.logs import STEP_FIELDS
from sim.uuv.simulate import TRAJECTORY_FIELDS

_COLS = [TRAJECTORY_FIELDS.index(k) for k in ("t", "x", "y", "heading", "energy_hj", "surfaced", "speed", "yaw_rate")]
_CMD = [TRAJECTORY_FIELDS.index(k) for k in ("heading_cmd", "speed_cmd")]


@dataclass
class SimRun:
    """The parts of :class:`planner.review.logs.LoggedRun` a fit reads."""

    steps: np.ndarray
    setpoints: np.ndarray
    meta: dict = field(default_factory=dict)
    scores: np.ndarray | None = None  # the batch's score vector of the run
    path: Path = Path("sim.mcap")

    @property
    def track(self) -> np.ndarray:
        return self.steps[:, :6]


def sim_runs(mission, U, bias=None, stochastic: bool = False, seed: int = 0, vehicle=None) -> list[SimRun]:
    """One :class:`SimRun` per row of ``U`` (rows must be valid scenarios)."""
    kw = {} if vehicle is None else {"plant": vehicle}
    r = sim.uuv.simulate(
        mission, np.atleast_2d(U), seed=seed, stochastic=stochastic, trajectories=True, bias=bias, **kw
    )
    out = []
    for k in range(len(r.trajectories)):
        tr = r.trajectory(k)
        assert tr is not None, "sim_runs: an invalid scenario has no run"
        steps = tr[:, _COLS].astype(float)
        assert steps.shape[1] == len(STEP_FIELDS)
        # the surface command: where the vehicle surfaced (at an ascent rate of 0 it surfaces the step it is told)
        surface = tr[:, TRAJECTORY_FIELDS.index("surfaced")] if mission.vehicle.ascent_rate_mps == 0 else np.nan
        sp = np.column_stack([tr[:, _CMD], np.broadcast_to(surface, tr.shape[:1])])
        sp[-1] = np.nan  # nothing is flown after the last step
        out.append(SimRun(steps, sp, {"mission": mission.name}, r.scores[k].copy(), Path(f"run{k}.mcap")))
    return out
