"""``rapt-plan selfright ROBOT.toml|ROBOT.urdf``: which tipped-over states can a robot right itself from, and how (chapter 5).

Runs the manifold-constrained adaptive search (:mod:`rapt.manifold`) on the robot's
stability function (:mod:`sim.robots`), builds the transition graph
(:mod:`rapt.transitions`) and writes ``OUT/graph.json``, ``OUT/graph.graphml``,
``OUT/states.png`` (state plots like Figures 5.4 and 5.7) and ``OUT/report.md``.
The same study functions drive ``benchmarks/selfright.py`` (grid search included).
"""

from __future__ import annotations

import json
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Optional

import numpy as np
import typer
from scipy.spatial import cKDTree

from planner.console import fail, out as console
from rapt.manifold import ManifoldSampler, angular_embedding, full_turn, manifold_search
from rapt.transitions import TransitionGraph, transition_graph
from sim.robots import Robot, RobotFileError, StabilityFunction, load_robot

__all__ = ["SelfRightStudy", "space_bounds", "adaptive_study", "grid_study", "analyse", "write_outputs",
           "selfright_command"]

def space_bounds(robot: Robot, planar: bool) -> np.ndarray:
    """Radian ranges of ``[θ, φ]``: joint ranges, then pitch (planar) or roll and pitch."""
    body = [[-np.pi, np.pi]] if planar else [[-np.pi, np.pi], [-np.pi / 2, np.pi / 2]]
    return np.concatenate([robot.joint_bounds, np.asarray(body)]).reshape(-1, 2)


def _to_unit(angles: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    span = hi - lo
    a = np.asarray(angles, dtype=float)
    full = full_turn(lo, hi)  # periodic coordinate: wrap into range
    a = np.where(full, lo + np.mod(a - lo, 2 * np.pi), a)
    return np.clip((a - lo) / span, 0.0, 1.0)


@dataclass
class SelfRightStudy:
    """Every evaluated state of one search, in unit-cube coordinates of :func:`space_bounds`."""

    robot: Robot
    slope: float  # degrees
    method: str
    bounds: np.ndarray
    n_free: int
    X: np.ndarray  # (N, d) starting states
    stable: np.ndarray
    rest: np.ndarray  # (N, d), NaN rows where it rolls away
    energy: np.ndarray
    faces: list  # per state: (k, b) valid body angles, unit cube
    queries: int
    seconds: float
    resolution: float | None = None  # grid spacing, radians
    extra: dict = field(default_factory=dict)
    ids: np.ndarray | None = None  # (N,) face identity of each starting state
    rest_ids: np.ndarray | None = None  # (N,) face identity of each resting state (-1: none)
    face_ids: list | None = None  # per state: (k,) identities of ``faces``

    def embed(self, U: np.ndarray) -> np.ndarray:
        return angular_embedding(U, self.bounds)

    def known_states(self, with_ids: bool = False):
        """``X^Z``: every hull face of every evaluated joint state, each once (unit cube); and their identities."""
        counts = np.array([len(f) for f in self.faces])
        K = np.column_stack([np.repeat(self.X[:, :self.n_free], counts, axis=0), np.concatenate(self.faces)])
        _, first = np.unique(_row_keys(K), return_index=True)
        first = np.sort(first)
        if not with_ids:
            return K[first]
        return K[first], (np.concatenate(self.face_ids)[first] if self.face_ids is not None else None)

    def extra_states(self, with_ids: bool = False, known: tuple | None = None):
        """Known states that were not themselves evaluated (Algorithm 8 labels them by nearest neighbour).

        ``known``: :meth:`known_states` ``(with_ids=True)`` when the caller already has it.
        """
        K, ids = self.known_states(with_ids=True) if known is None else known
        new = ~np.isin(_row_keys(K), _row_keys(self.X))
        if not with_ids:
            return K[new]
        return K[new], (ids[new] if ids is not None else None)


def _toward(a: np.ndarray, b: np.ndarray, periodic) -> np.ndarray:
    """``b − a`` in angles, the shorter way round on the ``periodic`` coordinates."""
    return np.where(periodic, np.mod(b - a + np.pi, 2 * np.pi) - np.pi, b - a)


def _row_keys(A: np.ndarray) -> np.ndarray:
    """Hashable keys of rows, equal for rows equal to ~1e-9."""
    R = np.ascontiguousarray(np.round(np.asarray(A, float), 9) + 0.0)
    return R.view(np.dtype((np.void, R.dtype.itemsize * R.shape[1]))).ravel()


class _System:
    """The stability function seen from the unit cube: queries in, used states, labels and faces out."""

    def __init__(self, robot: Robot, slope: float, whole_hulls: bool = False):
        self.F = StabilityFunction(robot, slope)
        self.whole_hulls = whole_hulls  # label every face of each queried joint state (one query per face)
        self.outcomes = False  # also tell the search where each state comes to rest
        self.bounds = space_bounds(robot, self.F.planar)
        self.m = robot.dof
        self.lo, self.hi = self.bounds[:, 0], self.bounds[:, 1]
        self.rows: list = []

    def angles(self, U: np.ndarray) -> np.ndarray:
        return self.lo + np.asarray(U, float) * (self.hi - self.lo)

    def unit(self, angles: np.ndarray) -> np.ndarray:
        return _to_unit(angles, self.lo, self.hi)

    def record(self, res) -> tuple[np.ndarray, np.ndarray, list]:
        m = self.m
        X = self.unit(np.column_stack([res.theta, res.start]))
        rest = np.column_stack([res.theta, res.rest])
        R = np.where(np.isfinite(rest).all(axis=1, keepdims=True), self.unit(np.nan_to_num(rest)), np.nan)
        faces, done = [], {}
        for t, f in zip(res.theta, res.faces):  # the states of one hull share its face array: convert it once
            if id(f) not in done:
                done[id(f)] = self.unit(np.column_stack([np.broadcast_to(t, (len(f), m)), f]))[:, m:]
            faces.append(done[id(f)])
        self.rows.append((X, res.stable.copy(), R, res.energy.copy(), res.start_id, res.rest_id, faces, res.face_ids))
        if self.outcomes:  # the resting face's identity (-1: rolls away), for the search's information
            return X, res.stable.astype(float), faces, res.start_id, res.face_ids, res.rest_id.astype(float)
        return X, res.stable.astype(float), faces, res.start_id, res.face_ids

    def __call__(self, U: np.ndarray, whole_hulls: bool | None = None):
        """Label the states ``U``; ``whole_hulls`` (default: the system's) labels every face of their joint states."""
        a = self.angles(U)
        if self.whole_hulls if whole_hulls is None else whole_hulls:
            return self.record(self.F.all_faces(np.unique(a[:, :self.m], axis=0)))
        return self.record(self.F(a[:, :self.m], a[:, self.m:]))

    def study(self, robot, slope, method, seconds, **kw) -> SelfRightStudy:
        X, s, R, e, ids, rest_ids = (np.concatenate([r[i] for r in self.rows]) for i in range(6))
        faces = [f for r in self.rows for f in r[6]]
        face_ids = [f for r in self.rows for f in r[7]]
        return SelfRightStudy(robot, slope, method, self.bounds, self.m, X, s.astype(bool), R, e, faces,
                              self.F.n_queries, seconds, ids=ids, rest_ids=rest_ids, face_ids=face_ids, **kw)


def adaptive_study(robot: Robot, slope: float, budget: int, *, seed: int = 0, batch_size: int = 50,
                   r_min_deg: float = 1.0, r_max_deg: float = 10.0, n_initial: int | None = None,
                   whole_hulls: bool | None = None, refine: float = 0.1, outcomes: bool = False, progress=None,
                   **options) -> SelfRightStudy:
    """Algorithm 6 on ``robot`` at ``slope`` degrees, about ``budget`` queries, then the transitions refined.

    A query is the stability of one state ``[θ, face]``, as the grid search counts them.
    ``refine`` is the share of the budget kept back for :func:`refine_transitions` (with
    whatever the search leaves when its resolution cut-offs end it first); 0 turns it off.
    What a refinement leaves goes back to the search, less the same share of it, and the
    study ends on a refinement (up to four), so that transitions the last search found are
    bisected too.
    ``whole_hulls`` labels every face of each queried joint state and counts each face as
    a query; otherwise only the snapped face is labelled (the other faces are known states
    labelled by their nearest neighbour in Algorithm 8).  Default: on for planar robots,
    whose faces are all settled in one table lookup once the hull is known (and whose
    nodes are otherwise mislabelled by sparse neighbours), off for 3-D hulls, where each
    face is its own tipping simulation with tens to hundreds of faces per hull.  The last
    batch may overshoot the budget by a few faces.  ``outcomes`` tells the search where each
    state comes to rest, so that neighbours on a face tipping to different faces count as a
    boundary (:mod:`rapt.manifold`): it finds stable islands narrower than a coarse r_max,
    which pays with a coarse r_max (1 DOF at 210 queries, r_max 45°: the grid's graph on 85 of 96
    held-out seeds against 52) and costs with a fine one, which resolves the extra boundaries
    (700 queries at r_max 10°, batch 50: 10 of 24 seeds against 18).
    """
    system = _System(robot, slope, False)
    whole_hulls = system.F.planar if whole_hulls is None else bool(whole_hulls)
    system.whole_hulls = whole_hulls
    system.outcomes = bool(outcomes)
    if n_initial is None:
        n_initial = min(max(20 * system.bounds.shape[0], 50), max(budget // 5, 10))
    sampler = ManifoldSampler(robot.dof, system.bounds, seed=seed, r_min=np.radians(r_min_deg),
                              r_max=np.radians(r_max_deg), n_initial=n_initial, whole_hulls=whole_hulls, **options)
    if not 0 <= refine < 1:
        raise ValueError(f"refine: expected a share of the budget in [0, 1), got {refine!r}")
    t0 = time.perf_counter()
    manifold_search(system, sampler, budget - int(round(refine * budget)), batch_size, progress)
    extra = dict(stopped_by_resolution=sampler.done, r_min_deg=r_min_deg, r_max_deg=r_max_deg,
                 whole_hulls=whole_hulls)
    rounds, spent = 0, 0
    for turn in range(4 if refine > 0 else 0):
        before = system.F.n_queries
        rounds += refine_transitions(system, robot, slope, budget, np.radians(r_min_deg),
                                     r_max=np.radians(r_max_deg), tell=sampler.tell)
        spent += system.F.n_queries - before
        if turn == 3 or sampler.done or system.F.n_queries >= budget:
            break
        # the pairs took less than was kept back: the search has the rest, bar the same share of it for
        # refining the transitions it finds (the search always ends before a refinement)
        manifold_search(system, sampler, budget - int(round(refine * (budget - system.F.n_queries))), batch_size,
                        progress)
    extra.update(search_queries=system.F.n_queries - spent, refine_queries=spent, refine_rounds=rounds)
    study = system.study(robot, slope, "adaptive", time.perf_counter() - t0)
    study.extra.update(extra, joint_states=system.F.n_hulls)
    return study


def refine_transitions(system: _System, robot: Robot, slope: float, budget: int, r_min: float, *,
                       r_max: float | None = None, max_rounds: int = 12, splits: int = 2, tell=None) -> int:
    """Cut every transition's boundary pair in ``splits`` parts (bisect it) until it is shorter than ``r_min`` (joint space).

    Section 5.5.1 prizes close boundary pairs (the transition point is known better), but
    the search spreads its budget over every boundary, most of them between faces no
    path uses.  So each edge of the graph has the states between its witness and its
    stable partner queried (equally spaced in joint angles, on the pair's face): the one
    next to the boundary becomes the new witness or partner, or shows a transition the
    search missed.  Each such state is asked alone, on the pair's face, even where the search
    labels whole hulls: the pair lies on that one face, and the hull's other faces (6 on
    the 1-DOF robot, more on 3 DOF) would cost a query each and tell the pair nothing (on
    3 DOF that took the matched pairs from 8.5° to 1.2° for the same budget).  The graph is
    rebuilt each round; a state already asked is not asked again, so a pair that cannot
    shrink is left as it is.  Stops when every pair is below
    ``r_min``, ``system`` has answered ``budget`` queries, or after ``max_rounds``;
    ``tell`` (e.g. the search's :meth:`~rapt.manifold.ManifoldSampler.tell`) hears every answer.
    Returns the number of rounds run.
    """
    asked: set = set()
    lo, span = system.lo, system.hi - system.lo
    periodic = full_turn(system.lo, system.hi)
    for rounds in range(max_rounds):
        left = budget - system.F.n_queries
        if left < 1:
            return rounds
        study = system.study(robot, slope, "adaptive", 0.0, extra={"r_max_deg": np.degrees(r_max)} if r_max else {})
        graph, extra, _, _ = build_graph(study)
        e = graph.edges
        todo = np.flatnonzero(e["length"] > r_min) if graph.n_edges else np.empty(0, int)
        # edges between the largest regions first (the paths most states take), then the longest pairs
        size = graph.node_sizes[np.maximum(e["src"][todo], e["dst"][todo])]  # the smaller region (nodes go by size)
        todo = todo[np.lexsort((-e["length"][todo], -size))]
        settled = np.isfinite(study.rest).all(axis=1)
        U = np.concatenate([study.X, study.rest[settled], extra])
        w, p = lo + U[e["witness"][todo]] * span, lo + U[e["partner"][todo]] * span  # angles
        d = _toward(w, p, periodic)
        frac = np.arange(1, splits) / splits
        Q = _to_unit((w[:, None] + frac[None, :, None] * d[:, None]).reshape(-1, len(lo)), system.lo, system.hi)
        keys = [k.tobytes() for k in _row_keys(Q[:, :study.n_free])]
        new, seen = [], set(asked)
        for i, k in enumerate(keys):
            if k not in seen:
                seen.add(k)
                new.append(i)
        if not new:
            return rounds
        new = new[:left]
        asked.update(keys[i] for i in new)
        answer = system(Q[new], whole_hulls=False)
        if tell is not None:
            tell(*answer)
    return max_rounds


def crossing_energies(study: SelfRightStudy, result: dict, tol_deg: float = 0.01) -> dict:
    """What each edge's transition loses at the boundary itself: its boundary pairs bisected to ``tol_deg``.

    A witness lies up to a pair's length past the boundary, where the face has already
    turned, so its energy is not what the robot loses when its joints carry it across: on
    the 2-DOF robot's edge 1 -> 0 the 1° grid's cheapest witness loses 4.65 J, the boundary
    it stands for 5.05 J.  So every transition of every edge is bisected in joint space, on
    the pair's faces (the witness's, or for a continuation the partner's; partner stable,
    witness tipping onto the same resting face), until the pair is under ``tol_deg``; a
    pair whose midpoint leaves both faces or tips elsewhere is left out (the robot moving
    from the partner would meet something else first).  A measurement, as a quasi-static sweep is:
    its queries go to a stability function of its own, not the study's.  Returns, aligned
    with ``result["graph"].edges``: ``energy`` (the lowest at the boundary; NaN when no pair
    resolved), ``pairs`` (how many resolved) and ``reported`` (the edge's own energy).
    """
    G: TransitionGraph = result["graph"]
    T, e = G.all_transitions, G.edges
    settled = np.isfinite(study.rest).all(axis=1)
    U = np.concatenate([study.X, study.rest[settled], result["extra_states"]])
    lo, hi = study.bounds[:, 0], study.bounds[:, 1]
    periodic = full_turn(lo, hi)
    m = study.n_free
    w = lo + U[T["witness"]] * (hi - lo)
    p = lo + U[T["partner"]] * (hi - lo)
    face, rest_face = study.ids[T["witness"]], study.rest_ids[T["witness"]]
    other = face if G.ids is None else G.ids[T["partner"]]  # a continuation's partner is on the face replacing it
    energy = study.energy[T["witness"]].astype(float).copy()
    ok = np.ones(len(w), dtype=bool)
    F = StabilityFunction(study.robot, study.slope)
    tol = np.radians(tol_deg)
    active = ok & (np.linalg.norm(_toward(w, p, periodic)[:, :m], axis=1) > tol)
    while active.any():
        k = np.flatnonzero(active)
        mid = w[k] + 0.5 * _toward(w[k], p[k], periodic)
        r = F(mid[:, :m], mid[:, m:])
        start, stable, rest, lost = r.start.copy(), r.stable.copy(), r.rest_id.copy(), r.energy.copy()
        for i in np.flatnonzero((r.start_id != face[k]) & (r.start_id != other[k])):  # a neighbouring face: ask
            on = np.flatnonzero(r.face_ids[i] == face[k[i]])                          # for the pair's own
            if not on.size:
                on = np.flatnonzero(r.face_ids[i] == other[k[i]])
            if not on.size:
                ok[k[i]] = False  # both faces are gone between partner and witness
                continue
            again = F(mid[i:i + 1, :m], r.faces[i][on[:1]])
            start[i], stable[i], rest[i], lost[i] = again.start[0], again.stable[0], again.rest_id[0], again.energy[0]
        here = ok[k]
        s = here & stable
        u = here & ~stable & (rest == rest_face[k])
        ok[k[here & ~s & ~u]] = False  # tips somewhere else: another transition lies between
        p[k[s], :m], p[k[s], m:] = mid[s, :m], start[s]
        w[k[u], :m], w[k[u], m:] = mid[u, :m], start[u]
        energy[k[u]] = lost[u]
        active = ok & (np.linalg.norm(_toward(w, p, periodic)[:, :m], axis=1) > tol)
    best = np.full(G.n_edges, np.nan)
    pairs = np.zeros(G.n_edges, dtype=int)
    for n, (s_, d_) in enumerate(zip(e["src"], e["dst"])):
        sel = ok & (T["src"] == s_) & (T["dst"] == d_)
        pairs[n] = int(sel.sum())
        if pairs[n]:
            best[n] = float(energy[sel].min())
    return {"energy": best, "pairs": pairs, "reported": np.asarray(e["energy"], float)}


def grid_study(robot: Robot, slope: float, resolution_deg: float) -> SelfRightStudy:
    """The baseline: every hull face of every joint state on a grid of ``resolution_deg`` degrees."""
    system = _System(robot, slope)
    axes = []
    for lo, hi in robot.joint_bounds:
        n = int(round((hi - lo) / np.radians(resolution_deg)))
        full = full_turn(lo, hi)
        axes.append(lo + np.arange(n if full else n + 1) * (hi - lo) / n)
    theta = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, robot.dof) if axes else np.zeros((1, 0))
    t0 = time.perf_counter()
    system.record(system.F.all_faces(theta))
    study = system.study(robot, slope, f"grid {resolution_deg:g}°", time.perf_counter() - t0,
                         resolution=np.radians(resolution_deg))
    study.extra.update(grid_shape=[len(a) for a in axes],
                       grid_periodic=[bool(full_turn(lo, hi)) for lo, hi in robot.joint_bounds])
    return study


def grid_connections(study: SelfRightStudy) -> tuple[np.ndarray, np.ndarray]:
    """A grid search's own connectivity (the original framework, section 5.2), for Algorithm 8.

    States on the same face (identity) at neighbouring grid joint states are connected, as
    is a face to the one replacing it at the neighbour (neither exists at the other joint
    state and the body angle moved no more than the joints: a continuation, as in
    :mod:`rapt.transitions`; the nearest such face, stable ones first when the face is
    stable); each resting state is the evaluated state it names.  Indices
    run over ``[X, settled rest states]`` (a grid has no unevaluated known states).
    """
    shape, periodic = study.extra["grid_shape"], study.extra["grid_periodic"]
    m = study.n_free
    U = study.X[:, :m]
    idx = np.empty((len(U), m), dtype=np.int64)
    for a in range(m):
        div = shape[a] if periodic[a] else shape[a] - 1
        idx[:, a] = np.rint(U[:, a] * div).astype(np.int64) % shape[a]
    flat = np.ravel_multi_index(tuple(idx.T), shape)
    settled = np.flatnonzero(np.isfinite(study.rest).all(axis=1))
    _, rank = np.unique(np.concatenate([study.ids, study.rest_ids[settled]]), return_inverse=True)
    rank = rank.reshape(-1).astype(np.int64)
    n_id = int(rank.max()) + 1
    key = flat * n_id + rank[:len(U)]
    order = np.argsort(key, kind="stable")
    skey = key[order]

    def find(k):
        at = np.clip(np.searchsorted(skey, k), 0, len(skey) - 1)
        return np.where(skey[at] == k, order[at], -1)

    N = len(U)
    src, dst = [np.arange(len(settled)) + N], [find(flat[settled] * n_id + rank[N:])]  # rest state = evaluated state
    by_flat = np.argsort(flat, kind="stable")
    first = np.searchsorted(flat[by_flat], np.arange(int(np.prod(shape))))
    count = np.bincount(flat, minlength=int(np.prod(shape)))
    body = study.embed(study.X)[:, 2 * m:]
    step = 2 * np.sin(study.resolution / 2)
    unsettled = 10.0 * step  # ranks an unstable replacement of a stable face after every stable one
    for a in range(m):
        nb = idx.copy()
        nb[:, a] += 1
        ok = nb[:, a] < shape[a]
        if periodic[a]:
            nb[:, a] %= shape[a]
            ok[:] = True
        s = np.flatnonzero(ok)
        nflat = np.ravel_multi_index(tuple(nb[s].T), shape)
        same = find(nflat * n_id + rank[s])
        src.append(s[same >= 0])
        dst.append(same[same >= 0])
        # this face has no namesake at the neighbour: look for what replaced it there.  A stable
        # face continues on the nearest stable replacement: when a corner pierces it, it splits
        # in two and the robot settles on the stable half, however near the other half lies.
        gone = s[same < 0]
        g_flat = nflat[same < 0]
        best, best_d = -np.ones(len(gone), dtype=np.int64), np.full(len(gone), np.inf)
        for o in range(int(count.max())):
            has = o < count[g_flat]
            c = by_flat[np.minimum(first[g_flat] + o, len(by_flat) - 1)]
            back = find(flat[gone] * n_id + rank[c])  # the replacement must not exist here either
            d = np.linalg.norm(body[c] - body[gone], axis=1)
            preference = d + unsettled * (study.stable[gone] & ~study.stable[c])
            take = has & (back < 0) & (d <= step + 1e-9) & (preference < best_d)
            best = np.where(take, c, best)
            best_d = np.where(take, preference, best_d)
        src.append(gone[best >= 0])
        dst.append(best[best >= 0])
    i, j = np.concatenate(src), np.concatenate(dst)
    keep = (i >= 0) & (j >= 0)
    return i[keep], j[keep]


def home_state(study: SelfRightStudy, with_id: bool = False):
    """The upright home state: home joint angles, resting on the face below the base (unit cube); and its face id."""
    F = StabilityFunction(study.robot, study.slope)
    res = F(study.robot.home[None], np.zeros((1, F.n_body)))
    U = _to_unit(np.concatenate([res.theta[0], res.start[0]]), study.bounds[:, 0], study.bounds[:, 1])
    return (U, int(res.start_id[0])) if with_id else U


@dataclass
class Probes:
    """Reference states for scoring graphs: every hull face of uniform random joint states, with the truth.

    ``U`` unit-cube states, ``ids`` their face identities, ``stable`` their true stability
    (evaluated outside any search, so they cost the searches nothing; planar robots only —
    settling every face of a 3-D hull is slow — else all True).
    """

    U: np.ndarray
    ids: np.ndarray
    stable: np.ndarray

    def __len__(self) -> int:
        return len(self.U)


def probe_states(robot: Robot, slope: float, n: int, seed: int) -> Probes:
    """Uniform random joint states with every hull face: the population 'self-rightable fraction' counts."""
    F = StabilityFunction(robot, slope)
    bounds = space_bounds(robot, F.planar)
    theta = bounds[:robot.dof, 0] + np.random.default_rng(seed).random((n, robot.dof)) * np.ptp(bounds[:robot.dof], axis=1)
    if F.planar:
        res = F.all_faces(theta)
        U = _to_unit(np.column_stack([res.theta, res.start]), bounds[:, 0], bounds[:, 1])
        return Probes(U, res.start_id, res.stable)
    rows, ids = [], []
    for t in theta:
        hull = F.hull(t)
        rows.append(np.column_stack([np.broadcast_to(t, (hull.n_faces, robot.dof)), hull.angles]))
        ids.append(hull.ids)
    U = _to_unit(np.concatenate(rows), bounds[:, 0], bounds[:, 1])
    return Probes(U, np.concatenate(ids), np.ones(len(U), dtype=bool))


def _probes(probes) -> Probes:
    """Accept a bare array of unit-cube states too (no identities, all taken as stable)."""
    if isinstance(probes, Probes):
        return probes
    U = np.asarray(probes, dtype=float)
    return Probes(U, None, np.ones(len(U), dtype=bool))


def default_max_edge(study: SelfRightStudy, known: np.ndarray | None = None) -> float:
    """Gabriel ``d_max`` (embedded distance).

    A grid: 2.5 steps (faces tilt with the joints, so neighbours on one face can be more
    than a step apart).  An adaptive study: three interior resolutions for planar robots
    (face identities keep different faces apart, so ``d_max`` need only bridge the sparse
    interior), two for 3-D hulls (body angles alone must keep faces apart), widened
    to twice the median distance from a known state to its (2m + 2)-th nearest (m joints)
    when the data are sparser than that, but at most four interior resolutions.
    ``known``: the study's :meth:`~SelfRightStudy.known_states` when the caller already has them.
    """
    if study.resolution is not None:
        return 2.5 * study.resolution
    r_max = np.radians(study.extra.get("r_max_deg", 10.0))
    base = 3.0 if study.X.shape[1] - study.n_free == 1 else 2.0
    E = study.embed(study.known_states() if known is None else known)
    k = min(len(E) - 1, 2 * study.n_free + 2)
    if k < 1:
        return base * r_max
    d, _ = cKDTree(E).query(E, k=k + 1)
    return float(min(max(base * r_max, 2.0 * np.median(d[:, -1])), 4.0 * r_max))


def build_graph(study: SelfRightStudy, *, max_edge: float | None = None, use_ids: bool | None = None):
    """Algorithm 8 on a study: (transition graph, extra states (unit cube), d_max, number of known states).

    ``use_ids`` keeps different hull faces apart by their vertex identity (section 5.2's
    unique-vertex faces); without it only ``max_edge`` does (body angles alone).  Default:
    on for planar robots (a face is a pair of corners), off for 3-D hulls, whose faces
    change identity with every mesh vertex that rises through them — the reason the
    chapter moved to body angles.
    """
    if use_ids is None:
        use_ids = study.X.shape[1] - study.n_free == 1
    known = study.known_states(with_ids=True)  # X^Z, once for d_max, the extra states and their identities
    max_edge = default_max_edge(study, known[0]) if max_edge is None else max_edge
    extra, extra_ids = study.extra_states(with_ids=True, known=known)
    ids = (study.ids, study.rest_ids, extra_ids) if use_ids and study.ids is not None else None
    connections = grid_connections(study) if use_ids and "grid_shape" in study.extra else None
    graph = transition_graph(study.embed(study.X), study.stable, study.embed(study.rest), study.energy,
                             study.embed(extra), max_edge=max_edge, ids=ids,
                             free_dims=2 * study.n_free, connections=connections)
    return graph, extra, max_edge, len(known[0])


def analyse(study: SelfRightStudy, *, max_edge: float | None = None, probes=None,
            use_ids: bool | None = None) -> dict:
    """Transition graph (:func:`build_graph`) and the chapter's figures of merit for one study."""
    t0 = time.perf_counter()
    graph, extra, max_edge, n_known = build_graph(study, max_edge=max_edge, use_ids=use_ids)
    seconds = time.perf_counter() - t0
    home_U, home_id = home_state(study, with_id=True)
    home = int(graph.node_of(study.embed(home_U[None]), ids=[home_id])[0])
    cost, _ = graph.costs_to(home) if home >= 0 else (np.full(graph.n_nodes, np.inf), None)
    probes = _probes(probe_states(study.robot, study.slope, 500, 0) if probes is None else probes)
    ok, energy = (graph.outcome(study.embed(probes.U), home, ids=probes.ids) if home >= 0
                  else (np.zeros(len(probes), bool), None))
    e = graph.edges
    return {
        "graph": graph, "home": home, "cost_to_home": cost, "graph_seconds": seconds, "max_edge": max_edge,
        "extra_states": extra,  # unit cube, in the graph's order (after the evaluated and resting states)
        "probes": probes, "probe_rightable": ok,  # compare_graphs reuses these for the same probes
        "queries": study.queries, "states": n_known, "nodes": graph.n_nodes, "edges": graph.n_edges,
        "rightable": float(ok.mean()) if len(probes) else float("nan"),
        "energy_to_home": float(energy[ok].mean()) if ok.any() else float("nan"),
        "pair_length_deg": float(np.degrees(e["length"]).mean()) if graph.n_edges else float("nan"),
        "transition_energy": float(e["energy"].mean()) if graph.n_edges else float("nan"),
    }


def _rightable(result: dict, study: SelfRightStudy, probes: Probes) -> np.ndarray:
    """Which probe states can reach the home node: :func:`analyse`'s own answer when it scored these probes."""
    if result.get("probes") is probes:
        return result["probe_rightable"]
    if result["home"] < 0:
        return np.zeros(len(probes), dtype=bool)
    return result["graph"].outcome(study.embed(probes.U), result["home"], ids=probes.ids)[0]


def compare_graphs(a: dict, study_a: SelfRightStudy, b: dict, study_b: SelfRightStudy, probes,
                   min_share: float = 0.01) -> dict:
    """Is graph ``a`` the same as ``b``?  Judged on probe states, since node numbers are arbitrary.

    Each truly stable probe state falls in one node of each graph (through its nearest
    known stable state on the same hull face); a node of ``a`` maps to the node of ``b``
    most of its probes fall in.  Nodes holding fewer than ``min_share`` of the stable
    probes are ignored.  Reports nodes and edges matched both ways, and the share of all
    probe states whose self-rightability agrees, and — over the edges matched in both
    graphs — the mean boundary-pair length and transition energy of each, and which edge of
    each they are (``matched_edges``: rows of indices into ``a``'s and ``b``'s edges).
    """
    probes = _probes(probes)
    ga, gb = a["graph"], b["graph"]
    st = probes.stable
    pid = None if probes.ids is None else probes.ids[st]
    na = ga.node_of(study_a.embed(probes.U[st]), ids=pid)
    nb = gb.node_of(study_b.embed(probes.U[st]), ids=pid)

    def big(nodes, n):
        share = np.bincount(nodes[nodes >= 0], minlength=n) / len(nodes)
        return set(np.flatnonzero(share >= min_share).tolist())

    big_a, big_b = big(na, ga.n_nodes), big(nb, gb.n_nodes)

    def mapping(src, dst, keep):
        out = {}
        for n in keep:
            d = dst[(src == n) & (dst >= 0)]
            out[n] = int(np.bincount(d).argmax()) if d.size else -1
        return out

    ab, ba = mapping(na, nb, big_a), mapping(nb, na, big_b)
    nodes_matched = sum(1 for n, m in ab.items() if ba.get(m) == n)

    def edge_set(g, keep, remap=None):
        """{(src, dst): (energy, boundary-pair length, edge index)}, the lowest-energy edge per mapped pair."""
        es = {}
        for k, (s, d, e, L) in enumerate(zip(g.edges["src"], g.edges["dst"], g.edges["energy"], g.edges["length"])):
            if s in keep and d in keep:
                key = (remap[s], remap[d]) if remap else (int(s), int(d))
                if key not in es or e < es[key][0]:
                    es[key] = (float(e), float(L), k)
        return es

    ea, eb = edge_set(ga, big_a, ab), edge_set(gb, big_b)
    both = sorted(set(ea) & set(eb))
    pair = np.array([[ea[k][1], eb[k][1]] for k in both]).reshape(-1, 2)
    energy = np.array([[ea[k][0], eb[k][0]] for k in both]).reshape(-1, 2)
    ra, rb = (_rightable(r, study, probes) for r, study in ((a, study_a), (b, study_b)))
    mean = lambda v: float(v.mean()) if v.size else float("nan")  # noqa: E731
    return {"nodes": (len(big_a), len(big_b)), "nodes_matched": nodes_matched, "edges": (len(ea), len(eb)),
            "edges_matched": len(both), "same": nodes_matched == len(big_a) == len(big_b) and set(ea) == set(eb),
            "rightable_agreement": float((ra == rb).mean()),
            # on the matched edges (the same transitions in both graphs): a's and b's means
            "pair_length_deg": (mean(np.degrees(pair[:, 0])), mean(np.degrees(pair[:, 1]))),
            "transition_energy": (mean(energy[:, 0]), mean(energy[:, 1])),
            "matched_edges": np.array([[ea[k][2], eb[k][2]] for k in both], dtype=int).reshape(-1, 2)}


# -- outputs ------------------------------------------------------------------------------------
def _state_degrees(study: SelfRightStudy, U: np.ndarray) -> dict:
    a = np.degrees(study.bounds[:, 0] + np.asarray(U, float) * np.ptp(study.bounds, axis=1))
    return {"joints_deg": [round(float(v), 3) for v in a[:study.n_free]],
            "body_deg": [round(float(v), 3) for v in a[study.n_free:]]}


def graph_document(study: SelfRightStudy, result: dict) -> dict:
    """The transition graph as plain JSON: nodes, one-way transitions, righting paths and the headline figures."""
    g: TransitionGraph = result["graph"]
    home = result["home"]
    cost = result["cost_to_home"]
    P = np.concatenate([study.X, study.rest[np.isfinite(study.rest).all(axis=1)], result["extra_states"]])
    nodes = []
    for n in range(g.n_nodes):
        members = np.flatnonzero(g.labels == n)
        rep = members[np.argmin(np.linalg.norm(g.points[members] - g.points[members].mean(axis=0), axis=1))]
        path = g.path(n, home) if home >= 0 and n != home else []
        nodes.append({"id": n, "states": int(g.node_sizes[n]), "home": n == home,
                      "can_right": bool(np.isfinite(cost[n])),
                      "energy_to_home_J": None if not np.isfinite(cost[n]) else round(float(cost[n]), 4),
                      "righting_path": [int(e) for e in path], "representative": _state_degrees(study, P[rep])})
    edges = []
    for e in range(g.n_edges):
        w = int(g.edges["witness"][e])
        edges.append({"id": e, "source": int(g.edges["src"][e]), "target": int(g.edges["dst"][e]),
                      "energy_J": round(float(g.edges["energy"][e]), 4),
                      "boundary_pair_deg": round(float(np.degrees(g.edges["length"][e])), 4),
                      "start": _state_degrees(study, study.X[w]), "rest": _state_degrees(study, study.rest[w])})
    return {"robot": study.robot.name, "slope_deg": study.slope, "method": study.method, "queries": study.queries,
            "known_states": result["states"], "max_edge_deg": round(float(np.degrees(result["max_edge"])), 4),
            "home_node": home, "self_rightable_fraction": round(result["rightable"], 4),
            "mean_energy_to_home_J": None if not np.isfinite(result["energy_to_home"]) else round(result["energy_to_home"], 4),
            "nodes": nodes, "edges": edges}


def write_graphml(doc: dict, path: Path) -> None:
    """GraphML (yEd, Gephi, networkx.read_graphml) of the node graph, written with xml.etree."""
    ns = "http://graphml.graphdrawing.org/xmlns"
    root = ET.Element("graphml", xmlns=ns)
    keys = [("states", "node", "int"), ("home", "node", "boolean"), ("can_right", "node", "boolean"),
            ("energy_to_home_J", "node", "double"), ("energy_J", "edge", "double"), ("boundary_pair_deg", "edge", "double")]
    for name, kind, typ in keys:
        ET.SubElement(root, "key", {"id": name, "for": kind, "attr.name": name, "attr.type": typ})
    graph = ET.SubElement(root, "graph", id=doc["robot"], edgedefault="directed")
    for n in doc["nodes"]:
        el = ET.SubElement(graph, "node", id=f"n{n['id']}")
        for name in ("states", "home", "can_right", "energy_to_home_J"):
            v = n[name]
            if v is not None:
                ET.SubElement(el, "data", key=name).text = str(v).lower() if isinstance(v, bool) else str(v)
    for e in doc["edges"]:
        el = ET.SubElement(graph, "edge", id=f"e{e['id']}", source=f"n{e['source']}", target=f"n{e['target']}")
        for name in ("energy_J", "boundary_pair_deg"):
            ET.SubElement(el, "data", key=name).text = str(e[name])
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)


def plot_states(study: SelfRightStudy, result: dict, path: Path, grid: SelfRightStudy | None = None) -> None:
    """State plots in the manner of Figures 5.4 and 5.7: each joint against each body angle.

    Blue: stable evaluated states; red: unstable ones; arrows: the graph's transitions
    (from the unstable witness to where it comes to rest).  With ``grid``, its known
    states are drawn underneath as black dots (Figure 5.4).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m, b = study.n_free, study.X.shape[1] - study.n_free
    names = [j.name for j in study.robot.joints] + (["pitch"] if b == 1 else ["roll", "pitch"])
    pairs = [(j, m + k) for k in range(b) for j in range(m)][:6] or [(m, m)]
    if b == 2:
        pairs = [(m, m + 1)] + pairs[:5]
    cols = min(len(pairs), 3)
    rows = int(np.ceil(len(pairs) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5.2 * cols, 4.4 * rows), squeeze=False)
    deg = np.degrees(study.bounds[:, 0] + study.X * np.ptp(study.bounds, axis=1))
    rest = np.degrees(study.bounds[:, 0] + study.rest * np.ptp(study.bounds, axis=1))
    g = result["graph"]
    for ax, (i, j) in zip(axes.flat, pairs):
        if grid is not None:
            gd = np.degrees(grid.bounds[:, 0] + grid.X * np.ptp(grid.bounds, axis=1))
            ax.scatter(gd[:, i], gd[:, j], s=0.2, c="k", alpha=0.25, lw=0, label=f"{grid.method} ({grid.queries:,})")
        for mask, colour, label in ((study.stable, "tab:blue", "stable"), (~study.stable, "tab:red", "unstable")):
            ax.scatter(deg[mask, i], deg[mask, j], s=4, c=colour, lw=0, label=label)
        for w in g.edges["witness"]:
            if np.isfinite(rest[w]).all():
                ax.annotate("", xy=(rest[w, i], rest[w, j]), xytext=(deg[w, i], deg[w, j]),
                            arrowprops=dict(arrowstyle="->", color="m", lw=0.8))
        ax.set_xlabel(f"{names[i]} (deg)")
        ax.set_ylabel(f"{names[j]} (deg)")
    for ax in list(axes.flat)[len(pairs):]:
        ax.axis("off")
    axes.flat[0].legend(loc="upper right", fontsize=7, markerscale=3)
    fig.suptitle(f"{study.robot.name}, slope {study.slope:g}°: {study.queries:,} queries, "
                 f"{g.n_nodes} nodes, {g.n_edges} transitions")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report_text(study: SelfRightStudy, doc: dict) -> str:
    lines = [f"# Self-righting study: {doc['robot']}", "",
             f"{study.robot.description}".strip(), "",
             f"- ground slope: {doc['slope_deg']:g}°",
             f"- queries to the stability function: {doc['queries']:,} ({study.method}, {study.seconds:.1f} s)",
             f"- known states (every hull face of every queried joint state): {doc['known_states']:,}",
             f"- transition graph: {len(doc['nodes'])} nodes (stable regions), {len(doc['edges'])} one-way transitions "
             f"(Gabriel d_max {doc['max_edge_deg']:g}°)",
             f"- home node (upright, home joint angles): {doc['home_node']}",
             f"- self-rightable fraction of states: {doc['self_rightable_fraction']:.1%}",
             "- mean transition energy to reach home: "
             + ("n/a" if doc["mean_energy_to_home_J"] is None else f"{doc['mean_energy_to_home_J']:.2f} J"), "",
             "![state plot](states.png)", "", "## Nodes", "",
             "| node | states | can right | energy to home (J) | path (edges) | representative joints (deg) | body (deg) |",
             "|---:|---:|:---:|---:|---|---|---|"]
    for n in doc["nodes"]:
        e = "-" if n["energy_to_home_J"] is None else f"{n['energy_to_home_J']:.2f}"
        lines.append(f"| {n['id']}{' (home)' if n['home'] else ''} | {n['states']:,} | {'yes' if n['can_right'] else 'no'} "
                     f"| {e} | {' → '.join(map(str, n['righting_path'])) or '-'} | {n['representative']['joints_deg']} "
                     f"| {n['representative']['body_deg']} |")
    lines += ["", "## Transitions (lowest-energy witness per pair of nodes)", "",
              "| edge | from | to | energy (J) | boundary pair (deg) | joints at the tip (deg) | body start → rest (deg) |",
              "|---:|---:|---:|---:|---:|---|---|"]
    for e in doc["edges"]:
        lines.append(f"| {e['id']} | {e['source']} | {e['target']} | {e['energy_J']:.2f} | {e['boundary_pair_deg']:.2f} "
                     f"| {e['start']['joints_deg']} | {e['start']['body_deg']} → {e['rest']['body_deg']} |")
    return "\n".join(lines) + "\n"


def write_outputs(study: SelfRightStudy, result: dict, out_dir: Path) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = graph_document(study, result)
    (out_dir / "graph.json").write_text(json.dumps(doc, indent=1) + "\n")
    write_graphml(doc, out_dir / "graph.graphml")
    plot_states(study, result, out_dir / "states.png")
    (out_dir / "report.md").write_text(report_text(study, doc))
    return doc


# -- command ------------------------------------------------------------------------------------
def selfright_command(
    robot_file: Annotated[Path, typer.Argument(metavar="ROBOT_FILE", help="Robot file, TOML or URDF (by suffix: .toml, "
                                               ".urdf), e.g. examples/robots/1dof.toml.")],
    out: Annotated[Path, typer.Option("--out", help="Directory for graph.json, graph.graphml, states.png, report.md.")],
    slope: Annotated[Optional[float], typer.Option(help="Ground slope in degrees (default: the robot file's, else 0).")] = None,
    budget: Annotated[int, typer.Option(help="Queries to the stability function (a planar robot's last hull may add a few faces).")] = 1000,
    seed: Annotated[int, typer.Option(help="Seed of every random choice.")] = 0,
    batch_size: Annotated[int, typer.Option("--batch-size", help="Queries per batch.")] = 50,
    r_min: Annotated[float, typer.Option("--r-min", help="Boundary resolution, degrees (search ends below it).")] = 1.0,
    r_max: Annotated[float, typer.Option("--r-max", help="Interior resolution, degrees.")] = 10.0,
    refine: Annotated[float, typer.Option("--refine", help="Share of the budget kept to bisect each transition's "
                                          "boundary pair below --r-min (0: off).")] = 0.1,
    outcomes: Annotated[bool, typer.Option("--outcomes", help="Also steer the search by where states tip to "
                                           "(finds stable islands narrower than a coarse --r-max such as 45; costs at a fine one).")] = False,
    max_edge: Annotated[Optional[float], typer.Option("--max-edge", help="Gabriel graph's longest edge, degrees "
                                                      "(default: 2 to 4 x --r-max, by sample density).")] = None,
) -> None:
    """Self-righting transition graph of a ground robot by manifold-constrained adaptive sampling (chapter 5)."""
    try:
        robot = load_robot(robot_file)
    except RobotFileError as exc:
        fail(str(exc))
    slope = robot.slope if slope is None else slope
    if not 0 <= slope < 90:
        fail(f"--slope: expected degrees in [0, 90), got {slope:g}")
    if budget < 10:
        fail(f"--budget: expected at least 10 queries, got {budget}")
    if batch_size < 1:
        fail(f"--batch-size: expected a positive number of queries, got {batch_size}")
    if not 0 < r_min <= r_max:
        fail(f"--r-min/--r-max: expected 0 < r_min <= r_max degrees, got {r_min:g} and {r_max:g}")
    if not 0 <= refine < 1:
        fail(f"--refine: expected a share of the budget in [0, 1), got {refine:g}")
    if max_edge is not None and max_edge <= 0:
        fail(f"--max-edge: expected degrees > 0, got {max_edge:g}")
    if out.exists() and not out.is_dir():
        fail(f"--out: {out} is a file; give a directory")
    study = adaptive_study(robot, slope, budget, seed=seed, batch_size=batch_size, r_min_deg=r_min, r_max_deg=r_max,
                           refine=refine, outcomes=outcomes)
    result = analyse(study, max_edge=None if max_edge is None else np.radians(max_edge))
    doc = write_outputs(study, result, out)
    energy = doc["mean_energy_to_home_J"]
    console.print(f"{robot.name} on a {slope:g}° slope: {study.queries:,} queries"
              f"{' (resolution reached)' if study.extra.get('stopped_by_resolution') else ''}, "
              f"{len(doc['nodes'])} nodes, {len(doc['edges'])} transitions; "
              f"self-rightable {doc['self_rightable_fraction']:.1%}, mean energy to home "
              f"{'n/a' if energy is None else f'{energy:.2f} J'}; wrote {out}/graph.json, graph.graphml, states.png, report.md",
              soft_wrap=True, highlight=False)
