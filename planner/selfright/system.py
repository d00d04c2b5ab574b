"""The robot's stability function as the searches see it: unit-cube queries in, labelled states out.

:class:`~sim.robots.StabilityFunction` works in radians and answers per joint state;
the manifold search (:mod:`rapt.manifold`) asks and learns in the unit cube.  This
adapter converts both ways, keeps every answered batch for the study record and hands
the search what its :meth:`~rapt.manifold.ManifoldSampler.tell` takes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from planner.selfright.space import space_bounds, to_unit
from planner.selfright.study import SelfRightStudy
from sim.robots import Robot, StabilityFunction

__all__ = ["Answer", "LabelledBatch", "StabilitySystem"]


class Answer(NamedTuple):
    """One batch's answer in the order :meth:`~rapt.manifold.ManifoldSampler.tell` takes it (``tell(*answer)``)."""

    X: np.ndarray  # the states used (the query snapped to a face), unit cube
    labels: np.ndarray  # 1.0 stable, 0.0 not
    faces: list  # per state: valid body angles at its joint state, unit cube
    ids: np.ndarray  # face identity of each state
    face_ids: list  # per state: identities of ``faces``
    outcomes: np.ndarray | None = None  # resting face's identity (-1: rolls away); None: not told


@dataclass(frozen=True)
class LabelledBatch:
    """What the stability function said about one batch of states, in unit-cube coordinates."""

    X: np.ndarray  # (n, d) starting states
    stable: np.ndarray  # (n,)
    rest: np.ndarray  # (n, d) resting states, NaN rows where it rolls away
    energy: np.ndarray  # (n,) potential energy lost
    ids: np.ndarray  # (n,) face identity of each starting state
    rest_ids: np.ndarray  # (n,) face identity of each resting state (-1: none)
    faces: list  # per state: (k, b) valid body angles
    face_ids: list  # per state: (k,) identities of ``faces``


class StabilitySystem:
    """The stability function seen from the unit cube: queries in, used states, labels and faces out."""

    def __init__(self, robot: Robot, slope: float, whole_hulls: bool = False):
        self.F = StabilityFunction(robot, slope)
        self.whole_hulls = whole_hulls  # label every face of each queried joint state (one query per face)
        self.outcomes = False  # also tell the search where each state comes to rest
        self.bounds = space_bounds(robot, self.F.planar)
        self.m = robot.dof
        self.lo, self.hi = self.bounds[:, 0], self.bounds[:, 1]
        self.batches: list[LabelledBatch] = []

    def angles(self, U: np.ndarray) -> np.ndarray:
        return self.lo + np.asarray(U, float) * (self.hi - self.lo)

    def unit(self, angles: np.ndarray) -> np.ndarray:
        return to_unit(angles, self.lo, self.hi)

    def record(self, res) -> Answer:
        """Keep one result of the stability function (unit cube) and return the search's view of it."""
        m = self.m
        X = self.unit(np.column_stack([res.theta, res.start]))
        rest = np.column_stack([res.theta, res.rest])
        R = np.where(np.isfinite(rest).all(axis=1, keepdims=True), self.unit(np.nan_to_num(rest)), np.nan)
        faces, done = [], {}
        for t, f in zip(res.theta, res.faces):  # the states of one hull share its face array: convert it once
            if id(f) not in done:
                done[id(f)] = self.unit(np.column_stack([np.broadcast_to(t, (len(f), m)), f]))[:, m:]
            faces.append(done[id(f)])
        self.batches.append(
            LabelledBatch(X, res.stable.copy(), R, res.energy.copy(), res.start_id, res.rest_id, faces, res.face_ids)
        )
        if self.outcomes:  # the resting face's identity (-1: rolls away), for the search's information
            return Answer(X, res.stable.astype(float), faces, res.start_id, res.face_ids, res.rest_id.astype(float))
        return Answer(X, res.stable.astype(float), faces, res.start_id, res.face_ids)

    def __call__(self, U: np.ndarray, whole_hulls: bool | None = None) -> Answer:
        """Label the states ``U``; ``whole_hulls`` (default: the system's) labels every face of their joint states."""
        a = self.angles(U)
        if self.whole_hulls if whole_hulls is None else whole_hulls:
            return self.record(self.F.all_faces(np.unique(a[:, : self.m], axis=0)))
        return self.record(self.F(a[:, : self.m], a[:, self.m :]))

    def study(self, robot, slope, method, seconds, **kw) -> SelfRightStudy:
        """Every batch so far as one study record."""
        b = self.batches
        X, s, R, e = (np.concatenate([getattr(r, k) for r in b]) for k in ("X", "stable", "rest", "energy"))
        ids, rest_ids = np.concatenate([r.ids for r in b]), np.concatenate([r.rest_ids for r in b])
        faces = [f for r in b for f in r.faces]
        face_ids = [f for r in b for f in r.face_ids]
        return SelfRightStudy(
            robot,
            slope,
            method,
            self.bounds,
            self.m,
            X,
            s.astype(bool),
            R,
            e,
            faces,
            self.F.n_queries,
            seconds,
            ids=ids,
            rest_ids=rest_ids,
            face_ids=face_ids,
            **kw,
        )
