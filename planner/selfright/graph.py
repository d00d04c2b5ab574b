"""Algorithm 8 on a self-righting study: the transition graph over its known states.

Which states count as neighbours differs by search (a grid's own neighbours, or a
Gabriel graph capped at ``d_max``) and by robot (face identities keep a planar robot's
faces apart; 3-D hulls rely on body angles).  Those choices are made here, once, for the
refinement of :mod:`planner.selfright.search` and for :mod:`planner.selfright.analysis`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from planner.selfright.study import SelfRightStudy
from rapt.errors import InputError
from rapt.transitions import TransitionGraph, transition_graph

__all__ = ["StudyGraph", "build_graph", "default_max_edge", "grid_connections"]


class StudyGraph(NamedTuple):
    """:func:`build_graph`'s answer."""

    graph: TransitionGraph
    extra_states: np.ndarray  # unit cube, in the graph's order (after the evaluated and resting states)
    max_edge: float  # Gabriel d_max used (embedded distance)
    n_known_states: int  # every hull face of every evaluated joint state, each once


def grid_connections(study: SelfRightStudy) -> tuple[np.ndarray, np.ndarray]:
    """A grid search's own connectivity (the original framework, section 5.2), for Algorithm 8.

    States on the same face (identity) at neighbouring grid joint states are connected, as
    is a face to the one replacing it at the neighbour (neither exists at the other joint
    state and the body angle moved no more than the joints: a continuation, as in
    :mod:`rapt.transitions`; the nearest such face, stable ones first when the face is
    stable); each resting state is the evaluated state it names.  Indices
    run over ``[X, settled rest states]`` (a grid has no unevaluated known states).
    """
    shape, periodic = study.grid_shape, study.grid_periodic
    if study.resolution is None or shape is None or periodic is None:
        raise InputError(f"study: a {study.method!r} study is not a grid; grid_connections needs grid_study's")
    m = study.n_free
    U = study.X[:, :m]
    idx = np.empty((len(U), m), dtype=np.int64)
    for a in range(m):
        div = shape[a] if periodic[a] else shape[a] - 1
        idx[:, a] = np.rint(U[:, a] * div).astype(np.int64) % shape[a]
    flat = np.asarray(np.ravel_multi_index(tuple(idx.T), shape))
    settled = np.flatnonzero(np.isfinite(study.rest).all(axis=1))
    _, rank = np.unique(np.concatenate([study.ids, study.rest_ids[settled]]), return_inverse=True)
    rank = rank.reshape(-1).astype(np.int64)
    n_id = int(rank.max()) + 1
    key = flat * n_id + rank[: len(U)]
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
    body = study.embed(study.X)[:, 2 * m :]
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
        nflat = np.asarray(np.ravel_multi_index(tuple(nb[s].T), shape))
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
    r_max = np.radians(10.0 if study.r_max_deg is None else study.r_max_deg)
    base = 3.0 if study.X.shape[1] - study.n_free == 1 else 2.0
    E = study.embed(study.known_states() if known is None else known)
    k = min(len(E) - 1, 2 * study.n_free + 2)
    if k < 1:
        return base * r_max
    d, _ = cKDTree(E).query(E, k=k + 1)
    return float(min(max(base * r_max, 2.0 * np.median(d[:, -1])), 4.0 * r_max))


def build_graph(study: SelfRightStudy, *, max_edge: float | None = None, use_ids: bool | None = None) -> StudyGraph:
    """Algorithm 8 on a study: the transition graph, its extra states, ``d_max`` and the number of known states.

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
    ids = (study.ids, study.rest_ids, extra_ids) if use_ids else None
    connections = grid_connections(study) if use_ids and study.grid_shape is not None else None
    graph = transition_graph(
        study.embed(study.X),
        study.stable,
        study.embed(study.rest),
        study.energy,
        study.embed(extra),
        max_edge=max_edge,
        ids=ids,
        free_dims=2 * study.n_free,
        connections=connections,
    )
    return StudyGraph(graph, extra, max_edge, len(known[0]))
