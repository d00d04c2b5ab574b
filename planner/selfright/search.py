"""The two searches of chapter 5 over a robot's states: adaptive manifold sampling and the grid baseline.

Both query the stability function through :class:`~planner.selfright.system.StabilitySystem`
and return a :class:`~planner.selfright.study.SelfRightStudy`, counting a query the same
way (one state ``[θ, face]``), so their graphs and costs can be compared directly.
"""

from __future__ import annotations

import time

import numpy as np

from planner.selfright.graph import build_graph
from planner.selfright.space import row_keys, to_unit, toward
from planner.selfright.study import SelfRightStudy
from planner.selfright.system import StabilitySystem
from rapt.errors import InputError
from rapt.manifold import ManifoldSampler, full_turn, manifold_search
from sim.robots import Robot

__all__ = ["adaptive_study", "refine_transitions", "grid_study"]


def adaptive_study(
    robot: Robot,
    slope: float,
    budget: int,
    *,
    seed: int = 0,
    batch_size: int = 50,
    r_min_deg: float = 1.0,
    r_max_deg: float = 10.0,
    n_initial: int | None = None,
    whole_hulls: bool | None = None,
    refine: float = 0.1,
    outcomes: bool = False,
    progress=None,
    **options,
) -> SelfRightStudy:
    """Algorithm 6 on ``robot`` at ``slope`` degrees, about ``budget`` queries, then the transitions refined.

    A query is the stability of one state ``[θ, face]``, as the grid search counts them.
    ``r_min_deg`` and ``r_max_deg`` are the boundary and interior resolutions: the search
    ends once its boundaries are resolved to the one and its interiors to the other.
    ``refine`` is the share of the budget kept back for :func:`refine_transitions` (with
    whatever the search leaves when its resolution cut-offs end it first); 0 turns it off.
    What a refinement leaves goes back to the search, less the same share of it, and the
    study ends on a refinement (up to four), so that transitions the last search found are
    bisected too.  The default is a small share because a refinement query moves one
    boundary pair, while the search needs most of the budget to find the boundaries.
    ``whole_hulls`` labels every face of each queried joint state and counts each face as
    a query; otherwise only the snapped face is labelled (the other faces are known states
    labelled by their nearest neighbour in Algorithm 8).  Default: on for planar robots,
    whose faces are all settled in one table lookup once the hull is known (and whose
    nodes are otherwise mislabelled by sparse neighbours), off for 3-D hulls, where each
    face is its own tipping simulation with tens to hundreds of faces per hull.  The last
    batch may overshoot the budget by a few faces.  ``outcomes`` tells the search where each
    state comes to rest, so that neighbours on a face tipping to different faces count as a
    boundary (:mod:`rapt.manifold`): it finds stable islands narrower than ``r_max``.  Off
    by default: with a fine ``r_max`` it costs queries, spent resolving the extra
    boundaries it reveals; it pays with a coarse ``r_max``, where such islands are
    otherwise stepped over.
    """
    system = StabilitySystem(robot, slope, False)
    whole_hulls = system.F.planar if whole_hulls is None else bool(whole_hulls)
    system.whole_hulls = whole_hulls
    system.outcomes = bool(outcomes)
    if n_initial is None:
        n_initial = min(max(20 * system.bounds.shape[0], 50), max(budget // 5, 10))
    sampler = ManifoldSampler(
        robot.dof,
        system.bounds,
        seed=seed,
        r_min=np.radians(r_min_deg),
        r_max=np.radians(r_max_deg),
        n_initial=n_initial,
        whole_hulls=whole_hulls,
        **options,
    )
    if not 0 <= refine < 1:
        raise InputError(f"refine: expected a share of the budget in [0, 1), got {refine!r}")
    t0 = time.perf_counter()
    manifold_search(system, sampler, budget - int(round(refine * budget)), batch_size, progress)
    stopped_by_resolution = sampler.done
    rounds, spent = 0, 0
    for turn in range(4 if refine > 0 else 0):
        before = system.F.n_queries
        rounds += refine_transitions(
            system, robot, slope, budget, np.radians(r_min_deg), r_max=np.radians(r_max_deg), tell=sampler.tell
        )
        spent += system.F.n_queries - before
        if turn == 3 or sampler.done or system.F.n_queries >= budget:
            break
        # the pairs took less than was kept back: the search has the rest, bar the same share of it for
        # refining the transitions it finds (the search always ends before a refinement)
        manifold_search(
            system, sampler, budget - int(round(refine * (budget - system.F.n_queries))), batch_size, progress
        )
    return system.study(
        robot,
        slope,
        "adaptive",
        time.perf_counter() - t0,
        r_min_deg=r_min_deg,
        r_max_deg=r_max_deg,
        whole_hulls=whole_hulls,
        stopped_by_resolution=stopped_by_resolution,
        search_queries=system.F.n_queries - spent,
        refine_queries=spent,
        refine_rounds=rounds,
        joint_states=system.F.n_hulls,
    )


def refine_transitions(
    system: StabilitySystem,
    robot: Robot,
    slope: float,
    budget: int,
    r_min: float,
    *,
    r_max: float | None = None,
    max_rounds: int = 12,
    splits: int = 2,
    tell=None,
) -> int:
    """Cut every transition's boundary pair in ``splits`` parts until it is shorter than ``r_min`` (joint space).

    Section 5.5.1 prizes close boundary pairs (the transition point is known better), but
    the search spreads its budget over every boundary, most of them between faces no
    path uses.  So each edge of the graph has the states between its witness and its
    stable partner queried (equally spaced in joint angles, on the pair's face): the one
    next to the boundary becomes the new witness or partner, or shows a transition the
    search missed.  Each such state is asked alone, on the pair's face, even where the search
    labels whole hulls: the pair lies on that one face, and the hull's other faces would
    cost a query each and tell the pair nothing.  The graph is rebuilt each round; a state
    already asked is not asked again, so a pair that cannot shrink is left as it is.
    Stops when every pair is below ``r_min``, ``system`` has answered ``budget`` queries,
    or after ``max_rounds``; ``tell`` (e.g. the search's
    :meth:`~rapt.manifold.ManifoldSampler.tell`) hears every answer.  ``splits`` = 2 bisects:
    one query per pair and round halves it, the cheapest step that always shrinks it.  Twelve
    halvings shrink a pair 4096-fold (45° to about 0.01°), so ``max_rounds`` is a safeguard
    rather than a resolution.
    ``r_max`` (radians) is the interior resolution the graph's ``d_max`` is derived from.
    Returns the number of rounds run.
    """
    asked: set = set()
    lo, span = system.lo, system.hi - system.lo
    periodic = full_turn(system.lo, system.hi)
    for rounds in range(max_rounds):
        left = budget - system.F.n_queries
        if left < 1:
            return rounds
        study = system.study(robot, slope, "adaptive", 0.0, r_max_deg=np.degrees(r_max) if r_max else None)
        built = build_graph(study)
        graph, extra = built.graph, built.extra_states
        e = graph.edges
        todo = np.flatnonzero(e["length"] > r_min) if graph.n_edges else np.empty(0, int)
        # edges between the largest regions first (the paths most states take), then the longest pairs
        size = graph.node_sizes[np.maximum(e["src"][todo], e["dst"][todo])]  # the smaller region (nodes go by size)
        todo = todo[np.lexsort((-e["length"][todo], -size))]
        settled = np.isfinite(study.rest).all(axis=1)
        U = np.concatenate([study.X, study.rest[settled], extra])
        w, p = lo + U[e["witness"][todo]] * span, lo + U[e["partner"][todo]] * span  # angles
        d = toward(w, p, periodic)
        frac = np.arange(1, splits) / splits
        Q = to_unit((w[:, None] + frac[None, :, None] * d[:, None]).reshape(-1, len(lo)), system.lo, system.hi)
        keys = [k.tobytes() for k in row_keys(Q[:, : study.n_free])]
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


def grid_study(robot: Robot, slope: float, resolution_deg: float) -> SelfRightStudy:
    """The baseline: every hull face of every joint state on a grid of ``resolution_deg`` degrees."""
    system = StabilitySystem(robot, slope)
    axes = []
    for lo, hi in robot.joint_bounds:
        n = int(round((hi - lo) / np.radians(resolution_deg)))
        full = full_turn(lo, hi)
        axes.append(lo + np.arange(n if full else n + 1) * (hi - lo) / n)
    theta = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, robot.dof) if axes else np.zeros((1, 0))
    t0 = time.perf_counter()
    system.record(system.F.all_faces(theta))
    return system.study(
        robot,
        slope,
        f"grid {resolution_deg:g}°",
        time.perf_counter() - t0,
        resolution=np.radians(resolution_deg),
        grid_shape=tuple(len(a) for a in axes),
        grid_periodic=tuple(bool(full_turn(lo, hi)) for lo, hi in robot.joint_bounds),
    )
