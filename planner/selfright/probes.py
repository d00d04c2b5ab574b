"""Reference states that score a transition graph: every hull face of random joint states, with the truth.

Graphs from different searches number their nodes arbitrarily and cover different
states, so they are judged on the same probe states, which are evaluated outside any
search and cost none of them a query.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.selfright.space import space_bounds, to_unit
from sim.robots import Robot, StabilityFunction, body_angles

__all__ = ["Probes", "probe_states", "orientation_probes", "as_probes"]


@dataclass
class Probes:
    """Reference states for scoring graphs: every hull face of uniform random joint states, with the truth.

    ``U`` unit-cube states, ``ids`` their face identities, ``stable`` their true stability
    (evaluated outside any search, so they cost the searches nothing; planar robots only —
    settling every face of a 3-D hull is slow — else all True).
    """

    U: np.ndarray
    ids: np.ndarray | None
    stable: np.ndarray

    def __len__(self) -> int:
        return len(self.U)


def probe_states(robot: Robot, slope: float, n: int, seed: int) -> Probes:
    """Uniform random joint states with every hull face: the population 'self-rightable fraction' counts."""
    F = StabilityFunction(robot, slope)
    bounds = space_bounds(robot, F.planar)
    theta = bounds[: robot.dof, 0] + np.random.default_rng(seed).random((n, robot.dof)) * np.ptp(
        bounds[: robot.dof], axis=1
    )
    if F.planar:
        res = F.all_faces(theta)
        U = to_unit(np.column_stack([res.theta, res.start]), bounds[:, 0], bounds[:, 1])
        return Probes(U, res.start_id, res.stable)
    rows, ids = [], []
    for t in theta:
        hull = F.hull(t)
        rows.append(np.column_stack([np.broadcast_to(t, (hull.n_faces, robot.dof)), hull.angles]))
        ids.append(hull.ids)
    U = to_unit(np.concatenate(rows), bounds[:, 0], bounds[:, 1])
    return Probes(U, np.concatenate(ids), np.ones(len(U), dtype=bool))


def orientation_probes(robot: Robot, slope: float, n: int, seed: int) -> Probes:
    """Uniform random joint states, each dropped in a uniform random orientation: the face it lands on, with the truth.

    :func:`probe_states` counts every hull face once, so a finely tessellated part (a rounded
    track end) weighs more than a large flat side; here a face counts by the share of
    orientations that snap onto it (the down direction uniform on the sphere), which does
    not depend on how the model is meshed.  The stability comes from the stability function.
    """
    F = StabilityFunction(robot, slope)
    bounds = space_bounds(robot, F.planar)
    rng = np.random.default_rng(seed)
    theta = bounds[: robot.dof, 0] + rng.random((n, robot.dof)) * np.ptp(bounds[: robot.dof], axis=1)
    down = rng.normal(size=(n, 3))
    down /= np.linalg.norm(down, axis=1, keepdims=True)
    if F.planar:  # the robot moves in the x-z plane: only the down direction's angle in it matters
        down[:, 1] = 0.0
    res = F(theta, body_angles(down, F.planar))
    U = to_unit(np.column_stack([res.theta, res.start]), bounds[:, 0], bounds[:, 1])
    return Probes(U, res.start_id, res.stable)


def as_probes(probes) -> Probes:
    """Accept a bare array of unit-cube states too (no identities, all taken as stable)."""
    if isinstance(probes, Probes):
        return probes
    U = np.asarray(probes, dtype=float)
    return Probes(U, None, np.ones(len(U), dtype=bool))
