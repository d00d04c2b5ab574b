"""A rehearsal: one scenario flown in the loop, then checked against the batch simulator.

``rapt-plan run`` flies a scenario of a mission, or of a field plan, through the
interfaces used on the water (:func:`planner.fly.sil.loop.run_sil`).  The loop adds no physics of
its own, so a deterministic flight must score exactly what the batch simulator scores
for the same row, bias and surrogate; a stochastic flight is scored from what the
navigation believed, so the batch's mode is the ground truth beside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.fly.flight import Flight
from sim.uuv.legs import leg_driver
from sim.uuv.scoring import MODE_NAMES

__all__ = ["BatchCheck", "fly", "check_against_batch"]


@dataclass(frozen=True)
class BatchCheck:
    """The batch simulator's verdict on the scenario a flight flew."""

    names: list  # the scores' names
    mode: str  # the batch's performance mode
    same: bool  # the flight scored exactly the batch's scores


def fly(
    flight: Flight,
    *,
    log_path=None,
    speedup=None,
    timeout_s: float = 600.0,
    bias=None,
    stochastic: bool = False,
    seed: int = 0,
    surrogate=None,
    bus_keys=None,
    live=None,
):
    """Fly ``flight`` software-in-the-loop (:func:`planner.fly.sil.loop.run_sil`); returns its :class:`~planner.fly.sil.loop.SilResult`.

    ``bus_keys``: the range's keys directory; the run's parts then join the secure bus each as its role.
    ``live``: ``(host, port)`` of a Foxglove live view of the run."""
    from planner.fly.sil.loop import run_sil

    return run_sil(
        flight.mission,
        flight.u,
        log_path=log_path,
        speedup=speedup,
        timeout_s=timeout_s,
        scenario_id=flight.scenario_id,
        mission_file=flight.mission_file,
        plan_id=flight.plan_id,
        bias=bias,
        stochastic=stochastic,
        seed=seed,
        surrogate=surrogate,
        bus_keys=bus_keys,
        legs=flight.legs,
        live=live,
    )


def check_against_batch(
    flight: Flight, scores: np.ndarray, *, bias=None, stochastic: bool = False, seed: int = 0, surrogate=None
) -> BatchCheck:
    """The batch simulator on the flight's row with the same bias, seed and surrogate (or legs), against its ``scores``."""
    import sim.uuv

    batch = sim.uuv.simulate(
        flight.mission,
        flight.u[None, :],
        bias=bias,
        seed=seed,
        stochastic=stochastic,
        surrogate=surrogate,
        driver=leg_driver(flight.legs) if flight.legs else None,
    )
    return BatchCheck(batch.names, MODE_NAMES[int(batch.modes[0])], bool(np.array_equal(scores, batch.scores[0])))
