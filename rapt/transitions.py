"""Transition graphs (Algorithm 8): stable regions as nodes, one-way transitions between them as edges.

Generic over the system: it takes labelled states in a metric space (the caller embeds
angles, e.g. with :func:`rapt.manifold.angular_embedding`), whether each is stable, the
state each unstable one comes to rest in, and the energy lost on the way.  Section 5.4.4:

1. All known states ``X^Z`` = the evaluated states, their resting states and any extra
   states known to lie on the constraint manifolds (the other hull faces at each joint
   state).  Labels of extra states come from their nearest evaluated state; resting
   states are stable by definition.
2. A Gabriel graph over ``X^Z`` with edges no longer than ``max_edge`` (which keeps
   parallel manifolds apart).  An extra state labelled unstable takes no part in a boundary
   pair and blocks none: no edge from it counts, and its label is a guess, which must not
   hide the boundary pair of the evaluated states around it (a single-face query of another
   face at that joint state put it there); between two stable states it still stands, as
   any unstable state does.  Candidates are all pairs within ``max_edge``
   (``cKDTree.query_pairs``); a pair is Gabriel when no third state lies strictly inside
   the ball it spans — exact, and cheaper than a Delaunay triangulation in 6+ dimensions.
3. The stable subgraph's connected components are the nodes.
4. Each unstable evaluated state adds an edge from the node of its nearest stable Gabriel
   neighbour (where the robot moved from, the other end of its *boundary pair*) to the
   node of its resting state, weighted by the energy lost; of duplicate edges between two
   nodes the lowest-energy one is kept.

:meth:`TransitionGraph.costs_to` runs Dijkstra on the reversed edges, giving every node's
lowest total energy to a goal node (infinite when it cannot reach it) and the path.

Manifold identities (optional).  When the system can name the manifold a state lies on
(a robot's hull face by its vertices), ``ids`` keeps states with different identities
apart: they are never Gabriel neighbours, never block each other's Gabriel edges, and an
extra state takes its label from the nearest evaluated state *of its own identity*.  This
is done by giving each identity its own far-apart slot in one extra coordinate, so the
same k-d tree code serves both cases.  Section 5.2 defines a node as continuously stable
states on one face; without identities ``max_edge`` alone must keep parallel faces apart.

A manifold can also *continue* as another: when a vertex rises through a resting face the
face is replaced by one with the same body angle at the crossing, and the robot turns
onto it without tipping.  With ``free_dims`` (the leading free coordinates, e.g. joint
angles), an edge between different identities is kept when neither identity exists at
the other state's free coordinates (one face replaced the other in between), the
constrained coordinates moved no more than the free ones (``rate`` 1), the edge is no
longer than ``continuation_edge`` (default ``max_edge / 2``: the crossing must be
resolved, or a long edge could step over an unstable band between two faces), and no
known state inside the ball it spans stands between the two faces — a Gabriel test in
which an unstable state of a third face, where one of the two faces also exists, does
not count (when a vertex splits a resting face in two, the robot settles on the stable
half and never rests on the other).
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from rapt.errors import InputError
from rapt.parallel import query_workers

__all__ = ["gabriel_graph", "TransitionGraph", "transition_graph"]


def gabriel_graph(X: np.ndarray, max_edge: float, chunk: int = 200_000) -> tuple[np.ndarray, np.ndarray]:
    """Edges ``(i, j)``, ``i < j``, of the Gabriel graph of ``X`` no longer than ``max_edge``.

    ``(i, j)`` is an edge when no other point lies strictly inside the ball with diameter
    ``x_i x_j``; any such point would be nearer the midpoint than ``x_i`` and ``x_j``, so it
    is among the 3 nearest neighbours of the midpoint.
    """
    X = np.asarray(X, dtype=float)
    if X.ndim != 2:
        raise InputError(f"X: expected a 2-D array of states, got shape {X.shape}")
    if not np.isfinite(max_edge) or max_edge <= 0:
        raise InputError(f"max_edge: expected a length > 0, got {max_edge}")
    if len(X) < 2:
        return np.empty(0, dtype=int), np.empty(0, dtype=int)
    tree = cKDTree(X)
    pairs = tree.query_pairs(max_edge, output_type="ndarray")
    pairs = pairs[_empty_balls(tree, X, pairs, chunk)]
    return pairs[:, 0].astype(int), pairs[:, 1].astype(int)


def _empty_balls(tree: cKDTree, X: np.ndarray, pairs: np.ndarray, chunk: int = 200_000) -> np.ndarray:
    """Per pair ``(i, j)``: is the ball with diameter ``x_i x_j`` free of other points (the Gabriel test)?"""
    keep = np.zeros(len(pairs), dtype=bool)
    for s in range(0, len(pairs), chunk):
        p = pairs[s : s + chunk]
        a, b = X[p[:, 0]], X[p[:, 1]]
        r = np.linalg.norm(a - b, axis=1) / 2.0
        d, idx = tree.query((a + b) / 2.0, k=min(3, len(X)), workers=query_workers(len(p)))
        d, idx = d.reshape(len(p), -1), idx.reshape(len(p), -1)
        other = (idx != p[:, :1]) & (idx != p[:, 1:2])
        inside = other & (d < r[:, None] * (1.0 - 1e-9) - 1e-15)
        keep[s : s + chunk] = ~inside.any(axis=1)
    return keep


def separate(X: np.ndarray, ids: np.ndarray | None, gap: float) -> np.ndarray:
    """``X`` with one more coordinate putting each identity ``gap`` from the next (unchanged without ids)."""
    X = np.asarray(X, dtype=float)
    if ids is None:
        return X
    _, rank = np.unique(np.asarray(ids).reshape(-1), return_inverse=True)
    return np.column_stack([X, rank.reshape(-1) * float(gap)])


@dataclass
class TransitionGraph:
    """Algorithm 8's ``G_N``: nodes are stable regions, directed edges one-way transitions.

    Attributes over all known states ``points`` (evaluated ``[:n_evaluated]``, then resting
    states, then extra states): ``stable``, ``labels`` (node of a stable state, else -1) and
    ``end_node`` (the node a state ends up in: its own, or its resting state's; -1 when
    unknown or when it never comes to rest).  ``edges`` has one row per kept transition:
    ``src``, ``dst``, ``energy``, ``witness`` (the evaluated unstable state), ``partner`` (the
    stable state it was reached from, an index into ``points``) and ``length`` (the boundary
    pair's length: witness to partner, in the free coordinates when ``free_dims`` is given —
    section 5.3's "distance in joint space").
    """

    points: np.ndarray
    stable: np.ndarray
    labels: np.ndarray
    end_node: np.ndarray
    n_evaluated: int
    node_sizes: np.ndarray
    edges: dict = field(default_factory=dict)
    all_transitions: dict = field(default_factory=dict)  # before de-duplication
    n_gabriel_edges: int = 0
    max_edge: float = 0.0
    ids: np.ndarray | None = None  # manifold identity of each of ``points`` (None: not known)

    @property
    def n_nodes(self) -> int:
        return len(self.node_sizes)

    @property
    def n_edges(self) -> int:
        return len(self.edges["src"])

    def node_of(self, points: np.ndarray, stable_only: bool = True, ids: np.ndarray | None = None) -> np.ndarray:
        """Node of the nearest known (stable, by default) state to each of ``points``.

        With ``ids`` (and a graph built with identities) the nearest state of the same
        identity is used when there is one, else the nearest of any.
        """
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        pool = np.flatnonzero(self.labels >= 0) if stable_only else np.arange(len(self.points))
        if pool.size == 0:
            return -np.ones(len(pts), dtype=int)
        src = self.labels if stable_only else self.end_node
        _, i = cKDTree(self.points[pool]).query(pts, k=1)
        out = src[pool[i]]
        if ids is not None and self.ids is not None:
            ids = np.asarray(ids).reshape(-1)
            gap = _gap(pts.shape[1], self.max_edge)
            known = np.unique(self.ids[pool])
            same = np.isin(ids, known)
            if same.any():
                allid = np.concatenate([self.ids[pool], ids[same]])
                sep = separate(np.concatenate([self.points[pool], pts[same]]), allid, gap)
                d, j = cKDTree(sep[: len(pool)]).query(sep[len(pool) :], k=1)
                out[np.flatnonzero(same)] = src[pool[j]]
        return out

    def costs_to(self, goal: int) -> tuple[np.ndarray, np.ndarray]:
        """Lowest total transition energy from every node to ``goal`` and the next edge on that path.

        Returns ``(cost, next_edge)``: ``cost[goal] = 0``, ``inf`` where ``goal`` is
        unreachable; ``next_edge[n]`` indexes :attr:`edges` (-1 at the goal or unreachable).
        """
        if not 0 <= goal < self.n_nodes:
            raise InputError(f"goal: expected a node in [0, {self.n_nodes}), got {goal}")
        into: dict[int, list[int]] = {}
        for e, d in enumerate(self.edges["dst"]):
            into.setdefault(int(d), []).append(e)
        cost = np.full(self.n_nodes, np.inf)
        nxt = -np.ones(self.n_nodes, dtype=int)
        cost[goal] = 0.0
        heap = [(0.0, goal)]
        while heap:
            c, n = heapq.heappop(heap)
            if c > cost[n]:
                continue
            for e in into.get(n, []):
                s = int(self.edges["src"][e])
                new = c + float(self.edges["energy"][e])
                if new < cost[s]:
                    cost[s], nxt[s] = new, e
                    heapq.heappush(heap, (new, s))
        return cost, nxt

    def path(self, start: int, goal: int) -> list[int]:
        """Edge indices of the lowest-energy path from node ``start`` to ``goal`` ([] if none or already there)."""
        cost, nxt = self.costs_to(goal)
        out, n = [], start
        while n != goal and nxt[n] >= 0:
            out.append(int(nxt[n]))
            n = int(self.edges["dst"][nxt[n]])
        return out if n == goal else []

    def outcome(self, points: np.ndarray, goal: int, ids: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """For states ``points``: can each reach ``goal`` (via its nearest known state's end node), and at what energy.

        The energy is the path's total from the node the state ends up in, the first fall
        of an unstable state excluded.
        """
        cost, _ = self.costs_to(goal)
        end = self.node_of(points, stable_only=False, ids=ids)
        c = np.where(end >= 0, cost[np.maximum(end, 0)], np.inf)
        return np.isfinite(c), c


def _gap(d: int, max_edge: float) -> float:
    """A separation between identities larger than any distance in the (embedded) space and than ``max_edge``."""
    return 4.0 * np.sqrt(max(d, 1)) + 2.0 * max_edge + 1.0


def _continuations(
    points: np.ndarray, ids: np.ndarray, stable: np.ndarray, free_dims: int, max_edge: float, rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """Gabriel edges between states of different identities where one manifold replaced the other."""
    tree = cKDTree(points)
    pairs = tree.query_pairs(max_edge, output_type="ndarray")
    i, j = pairs[:, 0].astype(int), pairs[:, 1].astype(int)
    cross = ids[i] != ids[j]
    i, j = i[cross], j[cross]
    if not len(i):
        return i, j
    _, group = np.unique(np.round(points[:, :free_dims], 12), axis=0, return_inverse=True)
    group = group.reshape(-1)
    _, rank = np.unique(ids, return_inverse=True)
    rank = rank.reshape(-1).astype(np.int64)
    n_id = int(rank.max()) + 1
    present = np.unique(group.astype(np.int64) * n_id + rank)  # (free state, identity) pairs that exist
    gone_j = ~np.isin(group[i].astype(np.int64) * n_id + rank[j], present)  # j's face absent at i's free state
    gone_i = ~np.isin(group[j].astype(np.int64) * n_id + rank[i], present)
    d = np.abs(points[i] - points[j])
    slow = np.linalg.norm(d[:, free_dims:], axis=1) <= rate * np.linalg.norm(d[:, :free_dims], axis=1) + 1e-9
    keep = gone_i & gone_j & slow
    i, j = i[keep], j[keep]
    # cheap passes first: most balls are empty, and most others hold a state of one of the two faces
    blocked = ~_empty_balls(tree, points, np.column_stack([i, j]))
    if blocked.any():
        b = np.flatnonzero(blocked)
        mid, r = (points[i[b]] + points[j[b]]) / 2.0, np.linalg.norm(points[i[b]] - points[j[b]], axis=1) / 2.0
        namesake = _namesake_inside(points, rank, i[b], j[b], mid, r, max_edge)
        rest = ~namesake
        blocked[b[rest]] = _blocked_continuations(
            tree, points, i[b[rest]], j[b[rest]], mid[rest], r[rest], ids, stable, group * np.int64(n_id), rank, present
        )
    return i[~blocked], j[~blocked]


def _namesake_inside(
    points: np.ndarray, rank: np.ndarray, i: np.ndarray, j: np.ndarray, mid: np.ndarray, r: np.ndarray, max_edge: float
) -> np.ndarray:
    """Per pair: does a state of ``i``'s or ``j``'s own identity lie strictly inside the ball (``mid``, ``r``) they span?"""
    gap = _gap(points.shape[1], max_edge)
    tree = cKDTree(separate(points, rank, gap))
    out = np.zeros(len(i), dtype=bool)
    k = min(3, len(points))
    for side in (i, j):
        d, idx = tree.query(np.column_stack([mid, rank[side] * gap]), k=k, workers=query_workers(len(i)))
        d, idx = d.reshape(len(i), -1), idx.reshape(len(i), -1)
        other = (idx != i[:, None]) & (idx != j[:, None])
        out |= (other & (d < r[:, None] * (1.0 - 1e-9) - 1e-15)).any(axis=1)
    return out


def _blocked_continuations(tree, points, i, j, mid, r, ids, stable, group_key, rank, present) -> np.ndarray:
    """Per pair: does a known state inside the ball (``mid``, ``r``) spanned by ``i`` and ``j`` stand between the faces?

    A state of either identity does (the edge should go through it: it may be unstable),
    and so does one at a free state where neither face exists (an unstable band, or a third
    face between them), and a stable state of a third face (the robot may settle on it on
    the way, as on a base face the moving face rotates past).  An unstable state of a third
    face where one of the two faces also exists does not: the robot never rests on it (when
    a vertex pierces a resting face the face splits in two and the robot settles on the
    stable half), so unlike in the Gabriel test it does not block.
    """
    found = tree.query_ball_point(mid, r) if len(i) else []
    pair = np.repeat(np.arange(len(i)), [len(f) for f in found])
    k = np.fromiter((x for f in found for x in f), dtype=np.int64, count=len(pair))
    a, b = i[pair], j[pair]
    inside = (k != a) & (k != b) & (np.linalg.norm(points[k] - mid[pair], axis=1) < r[pair] * (1.0 - 1e-9) - 1e-15)
    pair, k, a, b = pair[inside], k[inside], a[inside], b[inside]
    namesake = (ids[k] == ids[a]) | (ids[k] == ids[b])
    beside = np.isin(group_key[k] + rank[a], present) | np.isin(group_key[k] + rank[b], present)
    return np.bincount(pair[namesake | ~beside | stable[k]], minlength=len(i)) > 0


def transition_graph(
    X: np.ndarray,
    stable: np.ndarray,
    rest: np.ndarray,
    energy: np.ndarray,
    extra: np.ndarray | None = None,
    *,
    max_edge: float,
    ids: tuple | None = None,
    free_dims: int | None = None,
    rate: float = 1.0,
    continuation_edge: float | None = None,
    connections: tuple | None = None,
) -> TransitionGraph:
    """Build Algorithm 8's transition graph.

    Parameters
    ----------
    X: (N, d) evaluated starting states, in the metric space of the search.
    stable: (N,) whether each is stable.
    rest: (N, d) the state each comes to rest in (itself when stable; NaN rows when it never does).
    energy: (N,) energy lost between start and rest.
    extra: (M, d) further states known to lie on the manifolds (e.g. the other hull faces).
    max_edge: the Gabriel graph's maximum edge length ``d_max``.
    ids: optional manifold identities ``(of X (N,), of rest (N,), of extra (M,))``; see the module docstring.
    free_dims, rate, continuation_edge: with ``ids``, allow continuations between identities (module docstring).
    connections: ``(i, j)`` index arrays into ``[X, settled rest states, extra]`` used instead of
        the Gabriel graph — a grid search's own neighbours (the original framework, section 5.2),
        which a million-state grid can afford where a Gabriel graph cannot.
    """
    X, stable, rest, energy, extra, ids = _checked_inputs(X, stable, rest, energy, extra, ids)
    known = _known_states(X, stable, rest, extra, ids, _gap(X.shape[1], max_edge))
    # 2-3: Gabriel graph, stable subgraph, components
    i, j = _graph_edges(known, max_edge, connections, free_dims, rate, continuation_edge)
    labels, node_sizes = _nodes(known.stable, i, j)
    # 4: transitions from each unstable evaluated state's nearest stable Gabriel neighbour
    rest_node = -np.ones(known.n, dtype=int)
    rest_node[known.rest_idx] = labels[known.n : known.extra0]
    trans = _transitions(known, labels, rest_node, i, j, energy, free_dims)
    edges = _cheapest_edges(trans)
    # where every known state ends up
    end = labels.copy()
    end[: known.n] = np.where(stable, labels[: known.n], rest_node)
    if known.nearest is not None:  # an extra state ends where its label came from, unless it is stable
        E0 = known.extra0
        end[E0:] = np.where(known.stable[E0:], labels[E0:], end[: known.n][known.nearest])
    return TransitionGraph(
        known.points,
        known.stable,
        labels,
        end,
        known.n,
        node_sizes,
        edges,
        trans,
        int(len(i)),
        float(max_edge),
        known.ids,
    )


def _checked_inputs(X, stable, rest, energy, extra, ids) -> tuple:
    """:func:`transition_graph`'s arrays, shaped and checked (InputError naming the argument).

    Returns ``X``, ``stable``, ``rest``, ``energy``, ``extra`` and the identities as three
    int arrays (of X, rest, extra), or None without ``ids``.
    """
    X = np.asarray(X, dtype=float)
    N, d = X.shape if X.ndim == 2 else (-1, -1)
    if N < 0:
        raise InputError(f"X: expected a 2-D array of states, got shape {np.shape(X)}")
    stable = np.asarray(stable, dtype=bool).reshape(-1)
    rest = np.asarray(rest, dtype=float).reshape(N, d)
    energy = np.asarray(energy, dtype=float).reshape(-1)
    if stable.shape != (N,) or energy.shape != (N,):
        raise InputError(f"stable, energy: expected one value per state ({N}), got {stable.shape}, {energy.shape}")
    extra = np.empty((0, d)) if extra is None else np.asarray(extra, dtype=float).reshape(-1, d)
    if ids is not None:
        x_id, r_id, e_id = (np.asarray(v, dtype=np.int64).reshape(-1) for v in ids)
        if x_id.shape != (N,) or r_id.shape != (N,) or e_id.shape != (len(extra),):
            raise InputError(
                f"ids: expected identities for X ({N}), rest ({N}) and extra ({len(extra)}), "
                f"got {x_id.shape}, {r_id.shape}, {e_id.shape}"
            )
        ids = (x_id, r_id, e_id)
    return X, stable, rest, energy, extra, ids


@dataclass
class _KnownStates:
    """Step 1's known states ``X^Z``: the evaluated ones, then the settled resting states, then the extra ones."""

    points: np.ndarray
    ids: np.ndarray | None  # identity of each of ``points`` (None: not known)
    space: np.ndarray  # ``points`` with the identities set apart (:func:`separate`)
    stable: np.ndarray  # label of each of ``points``
    n: int  # evaluated states: ``points[:n]``
    settled: np.ndarray  # (n,) whether each evaluated state comes to rest
    rest_idx: np.ndarray  # the evaluated states whose resting states are ``points[n:extra0]``
    extra0: int  # index of the first extra state
    nearest: np.ndarray | None  # per extra state, the evaluated state its label comes from


def _known_states(
    X: np.ndarray, stable: np.ndarray, rest: np.ndarray, extra: np.ndarray, ids: tuple | None, gap: float
) -> _KnownStates:
    """Step 1: every known state and its label; an extra state takes its nearest evaluated state's."""
    N = len(X)
    settled = np.all(np.isfinite(rest), axis=1)
    rest_idx = np.flatnonzero(settled)
    points = np.concatenate([X, rest[rest_idx], extra])
    all_ids = None if ids is None else np.concatenate([ids[0], ids[1][rest_idx], ids[2]])
    space = separate(points, all_ids, gap)
    R0, E0 = N, N + len(rest_idx)
    lab = np.empty(len(points), dtype=bool)
    lab[:N] = stable
    lab[R0:E0] = True
    nn = None
    if len(extra):
        dist, nn = cKDTree(space[:N]).query(space[E0:], k=1)
        if ids is not None:  # an identity never evaluated: fall back to the nearest state of any identity
            lost = dist > gap / 2
            if lost.any():
                _, nn[lost] = cKDTree(X).query(extra[lost], k=1)
        lab[E0:] = stable[nn]
    return _KnownStates(points, all_ids, space, lab, N, settled, rest_idx, E0, nn)


def _graph_edges(
    known: _KnownStates,
    max_edge: float,
    connections: tuple | None,
    free_dims: int | None,
    rate: float,
    continuation_edge: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Step 2: the given connections, or the Gabriel graph (plus continuations between identities)."""
    points, space, lab, E0 = known.points, known.space, known.stable, known.extra0
    if connections is not None:
        i, j = (np.asarray(v, dtype=int).reshape(-1) for v in connections)
        if i.shape != j.shape or (i.size and (min(i.min(), j.min()) < 0 or max(i.max(), j.max()) >= len(points))):
            raise InputError(f"connections: expected two equal-length index arrays into the {len(points)} known states")
    else:
        # an extra state labelled unstable is a guess, and no edge from it counts: it neither takes part in a
        # boundary pair nor blocks one, but it still stands between two stable states, as any unstable state does
        keep = np.flatnonzero(np.r_[np.ones(E0, dtype=bool), lab[E0:]])
        i, j = gabriel_graph(space[keep], max_edge)
        i, j = keep[i], keep[j]
        if len(keep) < len(points):
            both = np.flatnonzero(lab[i] & lab[j])
            apart = ~_empty_balls(cKDTree(space), space, np.column_stack([i[both], j[both]]))
            i, j = np.delete(i, both[apart]), np.delete(j, both[apart])
    if connections is None and known.ids is not None and free_dims is not None:
        ci, cj = _continuations(
            points,
            known.ids,
            lab,
            free_dims,
            max_edge / 2 if continuation_edge is None else min(continuation_edge, max_edge),
            rate,
        )
        i, j = np.concatenate([i, ci]), np.concatenate([j, cj])
    return i, j


def _nodes(lab: np.ndarray, i: np.ndarray, j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Step 3: the stable subgraph's components, largest first; returns each state's node (-1: unstable)
    and the nodes' sizes."""
    both = lab[i] & lab[j]
    n_pts = len(lab)
    adj = coo_matrix((np.ones(both.sum()), (i[both], j[both])), shape=(n_pts, n_pts))
    _, comp = connected_components(adj, directed=False)
    comp = np.where(lab, comp, -1)
    uniq, counts = np.unique(comp[comp >= 0], return_counts=True)
    order = np.argsort(-counts, kind="stable")  # node 0 is the largest region
    relabel = -np.ones(comp.max() + 2 if comp.size else 1, dtype=int)
    relabel[uniq[order]] = np.arange(len(uniq))
    labels = np.where(comp >= 0, relabel[np.maximum(comp, 0)], -1)
    return labels, counts[order]


def _transitions(
    known: _KnownStates,
    labels: np.ndarray,
    rest_node: np.ndarray,
    i: np.ndarray,
    j: np.ndarray,
    energy: np.ndarray,
    free_dims: int | None,
) -> dict:
    """Step 4: one transition per unstable evaluated state that comes to rest, from the node of its nearest
    stable neighbour (its boundary pair) to its resting state's node, where the two nodes differ."""
    points, lab, N = known.points, known.stable, known.n
    cols = slice(None) if free_dims is None else slice(0, free_dims)  # section 5.3: pair length in joint space
    length = np.linalg.norm(points[i, cols] - points[j, cols], axis=1)
    a = np.concatenate([i, j])
    b = np.concatenate([j, i])
    ln = np.concatenate([length, length])
    sel = (a < N) & ~lab[a] & lab[b]
    a, b, ln = a[sel], b[sel], ln[sel]
    o = np.lexsort((ln, a))
    a, b, ln = a[o], b[o], ln[o]
    first = np.r_[True, a[1:] != a[:-1]] if a.size else np.empty(0, dtype=bool)
    u, nb, pair_len = a[first], b[first], ln[first]
    keep = known.settled[u]
    u, nb, pair_len = u[keep], nb[keep], pair_len[keep]
    src, dst = labels[nb], rest_node[u]
    ok = (src >= 0) & (dst >= 0) & (src != dst)
    return {
        "src": src[ok],
        "dst": dst[ok],
        "energy": energy[u[ok]],
        "witness": u[ok],
        "partner": nb[ok],
        "length": pair_len[ok],
    }


def _cheapest_edges(trans: dict) -> dict:
    """Of the transitions between the same two nodes, the lowest-energy one."""
    o = np.lexsort((trans["energy"], trans["dst"], trans["src"]))
    t = {k: v[o] for k, v in trans.items()}
    firstpair = (
        np.r_[True, (t["src"][1:] != t["src"][:-1]) | (t["dst"][1:] != t["dst"][:-1])] if len(o) else np.empty(0, bool)
    )
    return {k: v[firstpair] for k, v in t.items()}
