"""The plan's execution noise, drawn: seeded Gaussian dithers of scenarios, flown stochastic in one batch.

A plan scenario will not run on the water exactly as planned (:class:`planner.plan.dithering.DitherNoise`
states by how much, as a sigma per unit-cube coordinate that ``plan.json`` records under
``study.dithering.sigma_u``).  :func:`dithered_runs` is that noise: the plan's dithering
(:func:`planner.plan.dithering.dither_many`) measures with it how often a scenario shows its
prediction, and ``rapt-plan compare`` (:mod:`planner.review.forecast`) forecasts the day's runs
with it, there also under draws of the fitted execution bias.  One function, so the plan and
the review draw the same noise.
"""

from __future__ import annotations

import numpy as np

import sim.uuv
from sim.uuv.mission import Mission, Vehicle

__all__ = ["dithered_runs", "noise_kind", "coordinate_kinds", "NOISE_KINDS"]

#: The kinds of execution noise, in their units: navigation error on positions (m), start and timing slip on
#: times (s), gauge error on the starting charge (% of capacity).
NOISE_KINDS = {"position": "m", "time": "s", "battery": "%"}


def noise_kind(field: str) -> str | None:
    """Which execution noise a mission-file field takes (None: it is not noisy on the water)."""
    if field in ("x", "y"):
        return "position"
    if field.endswith("_s"):
        return "time"
    if field == "start_battery":
        return "battery"
    return None


def coordinate_kinds(mission: Mission) -> list[str | None]:
    """The noise kind of each unit-cube coordinate of ``mission``'s study space (None: not noisy, or not continuous)."""
    space = mission.space
    out: list[str | None] = [None] * space.dim
    for binding in mission.bindings:
        param = next(p for p in space.parameters if p.name == binding.parameter)
        if param.kind != "continuous":
            continue
        kind = noise_kind(binding.field)
        for c in range(space.dim)[space.slice_of(param.name)]:
            out[c] = kind
    return out


def dithered_runs(
    mission: Mission,
    centres: np.ndarray,
    n: int,
    sigma: np.ndarray,
    seed: int,
    surrogate=None,
    bias=None,
    plant: Vehicle | None = None,
) -> tuple[np.ndarray, sim.uuv.Result]:
    """``n`` seeded Gaussian dithers of each centre, the first the centre itself, run stochastic in one batch.

    Each unit-cube coordinate moves by ``sigma`` (clipped to the cube); the runs have the
    simulator's stochastic effects on (navigation drift, current perturbations).  ``bias``
    (anything :func:`sim.uuv.simulate` takes: one bias, or one per run in the order below)
    and ``plant`` fly the runs with a biased range and another vehicle.  Returns the dithers'
    unit-cube rows, (k, n, d), and their runs in that order (k * n rows).
    """
    k, d = centres.shape
    rng = np.random.default_rng(seed)
    U = np.clip(centres[:, None, :] + np.asarray(sigma) * rng.standard_normal((k, n, d)), 0.0, 1.0)
    U[:, 0] = centres
    X = U.reshape(k * n, d)
    return U, sim.uuv.simulate(mission, X, seed=seed, stochastic=True, bias=bias, surrogate=surrogate, plant=plant)
