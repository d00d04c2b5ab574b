"""Table 5.1's baseline: PRM-style connection of a study's stable states with a linear local planner.

Section 5.4.4 compares Algorithm 8's Gabriel clustering with "the PRM algorithm for
connecting states in C-space using our linear local planner", which "checks the linear
path between two states for stability".  Here every pair of stable known states within the
Gabriel graph's ``d_max`` is an edge to check; a pair is connected when every state on the
straight line between them (in angles, the shorter way round, one state every ``step_deg``
of the largest coordinate's change) snaps to a stable face near the line.  The connected
components are the PRM's nodes; with Algorithm 8's transitions relabelled by them they make
a transition graph to hold against the Gabriel one (:func:`same_graph`).

The path states of many edges are checked at once with the hull-free planar snap
(:func:`sim.robots.planar.planar_snap`, equal to the stability function's answer), coarse
steps first: an edge is dropped at its first unstable state, as any local planner stops at
its first collision (``early_exit=False`` checks every step of every edge).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from planner.selfright.analysis import SelfRightAnalysis
from planner.selfright.space import toward
from planner.selfright.study import SelfRightStudy
from rapt.errors import InputError
from rapt.manifold import full_turn
from sim.robots import StabilityFunction
from sim.robots.planar import planar_snap

__all__ = ["PRMResult", "GraphAgreement", "prm_connect", "same_graph"]

_STRIDE = 8  # every 8th path state first, so a failing edge is usually dropped early


@dataclass(frozen=True)
class PRMResult:
    """:func:`prm_connect`'s answer; ``labels`` runs over the Gabriel graph's ``points``."""

    labels: np.ndarray  # PRM component of each known state (-1: unstable, not a PRM state)
    seconds: float  # the local planner's checks and the components
    edges_checked: int
    edges_connected: int
    evaluations: int  # path states evaluated
    path_states: int  # path states on all checked edges (what checking every step would evaluate)


@dataclass(frozen=True)
class GraphAgreement:
    """Gabriel nodes against PRM nodes (:func:`same_graph`); pairs are ``(Gabriel's, PRM's)``."""

    nodes: tuple[int, int]  # nodes holding at least ``min_share`` of the stable states
    nodes_matched: int  # nodes mapping onto each other both ways (by where most of their states lie)
    edges: tuple[int, int]  # distinct transitions between those nodes
    edges_matched: int
    states_agreeing: float  # share of stable states in a matched pair of nodes
    same: bool  # every node and edge matched


def _steps(ang: np.ndarray, pairs: np.ndarray, step: float, periodic) -> tuple[np.ndarray, np.ndarray]:
    """Per pair the move from its first state to its second (angles, the shorter way round on full
    turns) and its number of steps (the path states between them are steps 1 .. steps - 1)."""
    d = toward(ang[pairs[:, 0]], ang[pairs[:, 1]], periodic)
    steps = np.maximum(np.ceil(np.abs(d).max(axis=1) / step - 1e-9).astype(np.int64), 1)
    return d, steps


def _stay_on(face_a, face_b, phi_a, phi_b, joint_move) -> np.ndarray:
    """Two states in a row of a path lie on one manifold: the same face, or one face replacing another
    (body angles apart by no more than the joints moved, the continuation rule of :mod:`rapt.transitions`)."""
    jump = np.abs(np.angle(np.exp(1j * (phi_b - phi_a))))
    return (face_a == face_b) | (jump <= joint_move + 1e-9)


def _check_chunk(F, ang, ids, pairs, d, steps, m, early_exit) -> tuple[np.ndarray, int]:
    """Which of these pairs the local planner connects, and the path states it evaluated.

    Every path state must snap to a stable face, and the snapped states, from one end to the
    other, must stay on one manifold (:func:`_stay_on`): interpolate, then project, as
    constrained planners do; a projection jumping to another face breaks the path.
    """
    inner = steps - 1
    edge = np.repeat(np.arange(len(pairs)), inner)
    k = np.arange(len(edge)) - np.repeat(np.cumsum(inner) - inner, inner) + 1  # step index 1 .. steps-1
    ok = np.ones(len(pairs), dtype=bool)
    evals = 0

    def snap(sel):
        e = edge[sel]
        path = ang[pairs[e, 0]] + (k[sel] / steps[e])[:, None] * d[e]
        return planar_snap(F, path[:, :m], path[:, m])

    if early_exit and edge.size:  # every stride-th state first: most failing edges fail there
        sel = np.flatnonzero(k % _STRIDE == 0)
        ok[np.unique(edge[sel][~snap(sel)[1]])] = False
        evals += sel.size
    sel = np.flatnonzero(ok[edge])
    if not sel.size:
        sel = np.zeros(0, dtype=np.int64)
    phi, stable, face = snap(sel)
    evals += sel.size
    e = edge[sel]
    ok[np.unique(e[~stable])] = False
    move = np.abs(d[:, :m]).max(axis=1) / steps  # joint move between states in a row
    i, j = pairs[:, 0], pairs[:, 1]
    # the chain of each edge: its first end, its path states, its second end
    first = np.r_[True, e[1:] != e[:-1]] if e.size else np.empty(0, dtype=bool)
    last = np.r_[e[1:] != e[:-1], True] if e.size else np.empty(0, dtype=bool)
    inside = ~first
    breaks = [
        e[inside][~_stay_on(face[:-1][inside[1:]], face[inside], phi[:-1][inside[1:]], phi[inside], move[e[inside]])],
        e[first][~_stay_on(ids[i[e[first]]], face[first], ang[i[e[first]], m], phi[first], move[e[first]])],
        e[last][~_stay_on(face[last], ids[j[e[last]]], phi[last], ang[j[e[last]], m], move[e[last]])],
    ]
    direct = np.flatnonzero(inner == 0)  # neighbours a step apart or less: their ends in a row
    breaks.append(direct[~_stay_on(ids[i[direct]], ids[j[direct]], ang[i[direct], m], ang[j[direct], m], move[direct])])
    ok[np.concatenate(breaks)] = False
    return ok, evals


def prm_connect(
    study: SelfRightStudy,
    result: SelfRightAnalysis,
    step_deg: float = 1.0,
    early_exit: bool = True,
    chunk: int = 10_000,
) -> PRMResult:
    """Connect the stable known states of ``result``'s graph with the linear local planner; components as nodes.

    Candidate edges: every pair of stable known states within ``result.max_edge`` (the
    Gabriel ``d_max``, embedded distance).  ``chunk`` path states are checked at a time.
    Planar robots only (the 1-, 2- and 3-DOF robots of Table 5.1).
    """
    if study.X.shape[1] - study.n_free != 1:
        raise InputError("study: the PRM baseline checks planar robots only (one body angle)")
    g = result.graph
    t0 = time.perf_counter()
    stable_pts = np.flatnonzero(g.labels >= 0)
    pairs = cKDTree(g.points[stable_pts]).query_pairs(result.max_edge, output_type="ndarray")
    settled = np.isfinite(study.rest).all(axis=1)
    known = np.concatenate([study.X, study.rest[settled], result.extra_states])[stable_pts]
    ang = study.bounds[:, 0] + known * np.ptp(study.bounds, axis=1)
    # face identities of the ends (a graph built without them: one shared identity, body angles alone decide)
    ids = np.full(len(stable_pts), -1, dtype=np.int64) if g.ids is None else g.ids[stable_pts]
    step = np.radians(step_deg)
    d, steps = _steps(ang, pairs, step, full_turn(study.bounds[:, 0], study.bounds[:, 1]))
    F = StabilityFunction(study.robot, study.slope)
    ok = np.ones(len(pairs), dtype=bool)
    evals, lo = 0, 0
    ends = np.cumsum(steps - 1)  # path states up to and including each pair
    while lo < len(pairs):  # about ``chunk`` path states at a time
        done = ends[lo - 1] if lo else 0
        hi = max(int(np.searchsorted(ends, done + chunk, side="right")), lo + 1)
        s = slice(lo, hi)
        ok[s], n = _check_chunk(F, ang, ids, pairs[s], d[s], steps[s], study.n_free, early_exit)
        evals, lo = evals + n, hi
    n_pts = len(stable_pts)
    adj = coo_matrix((np.ones(ok.sum()), (pairs[ok, 0], pairs[ok, 1])), shape=(n_pts, n_pts))
    _, comp = connected_components(adj, directed=False)
    labels = -np.ones(len(g.points), dtype=int)
    labels[stable_pts] = comp
    return PRMResult(labels, time.perf_counter() - t0, len(pairs), int(ok.sum()), evals, int((steps - 1).sum()))


def _transitions(result: SelfRightAnalysis, study: SelfRightStudy, labels: np.ndarray) -> set:
    """Algorithm 8's transitions (partner's node → resting state's node) under a node labelling."""
    T = result.graph.all_transitions
    settled = np.isfinite(study.rest).all(axis=1)
    rest_at = len(study.X) + np.cumsum(settled) - 1  # index of each evaluated state's resting state
    src, dst = labels[T["partner"]], labels[rest_at[T["witness"]]]
    keep = (src >= 0) & (dst >= 0) & (src != dst)
    return set(zip(src[keep].tolist(), dst[keep].tolist()))


def same_graph(
    result: SelfRightAnalysis, study: SelfRightStudy, prm: PRMResult, min_share: float = 0.01
) -> GraphAgreement:
    """Do Gabriel clustering and the PRM build the same graph from the same states?

    Nodes are compared on the stable known states both label: a node maps to the node
    of the other graph where most of its states lie; nodes holding fewer than ``min_share``
    of the states are left out, as in :func:`~planner.selfright.analysis.compare_graphs`.
    Edges: Algorithm 8's transitions, each from its boundary partner's node to its resting
    state's node, under either labelling.
    """
    ga, gp = result.graph.labels, prm.labels
    both = (ga >= 0) & (gp >= 0)
    a, p = ga[both], gp[both]

    def big(lab):
        return set(np.flatnonzero(np.bincount(lab) >= min_share * len(lab)).tolist())

    def node_map(src, dst, keep):
        return {n: int(np.bincount(dst[src == n]).argmax()) for n in keep}

    big_a, big_p = big(a), big(p)
    ap, pa = node_map(a, p, big_a), node_map(p, a, big_p)
    matched = {n for n, m in ap.items() if pa.get(m) == n}
    ea = {(ap[s], ap[t]) for s, t in _transitions(result, study, ga) if s in big_a and t in big_a}
    ep = {e for e in _transitions(result, study, gp) if e[0] in big_p and e[1] in big_p}
    agree = np.isin(a, list(matched)) & (p == np.array([ap.get(n, -1) for n in a]))
    return GraphAgreement(
        nodes=(len(big_a), len(big_p)),
        nodes_matched=len(matched),
        edges=(len(ea), len(ep)),
        edges_matched=len(ea & ep),
        states_agreeing=float(agree.mean()) if agree.size else float("nan"),
        same=len(matched) == len(big_a) == len(big_p) and ea == ep,
    )
