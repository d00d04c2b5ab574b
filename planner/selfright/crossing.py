"""Energies at the boundary itself: each transition's boundary pairs bisected until they meet.

A graph's edge reports its witness's energy, but the witness lies up to a pair's length
past the boundary.  Measuring what the robot loses when its joints carry it across the
boundary needs more queries than a search spends, so this is a measurement of its own,
for comparing searches fairly, not part of any search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.selfright.analysis import SelfRightAnalysis
from planner.selfright.space import toward
from planner.selfright.study import SelfRightStudy
from rapt.manifold import full_turn
from rapt.transitions import TransitionGraph
from sim.robots import StabilityFunction

__all__ = ["CrossingEnergies", "crossing_energies"]


@dataclass(frozen=True)
class CrossingEnergies:
    """Per edge of a graph, aligned with its ``edges`` (:func:`crossing_energies`)."""

    energy: np.ndarray  # the lowest energy lost at the boundary itself (NaN: no pair resolved)
    pairs: np.ndarray  # how many of the edge's boundary pairs resolved
    reported: np.ndarray  # the edge's own energy, as the graph reports it


def crossing_energies(study: SelfRightStudy, result: SelfRightAnalysis, tol_deg: float = 0.01) -> CrossingEnergies:
    """What each edge's transition loses at the boundary itself: its boundary pairs bisected to ``tol_deg``.

    A witness lies up to a pair's length past the boundary, where the face has already
    turned, so its energy is not what the robot loses when its joints carry it across; the
    longer a search's pairs, the further its reported energies can lie from the boundary's.
    So every transition of every edge is bisected in joint space, on
    the pair's faces (the witness's, or for a continuation the partner's; partner stable,
    witness tipping onto the same resting face), until the pair is under ``tol_deg``; a
    pair whose midpoint leaves both faces or tips elsewhere is left out (the robot moving
    from the partner would meet something else first).  A measurement, as a quasi-static sweep is:
    its queries go to a stability function of its own, not the study's.  ``tol_deg`` = 0.01°
    lies far below any search's boundary resolution, so what it measures is the boundary's.
    """
    G: TransitionGraph = result.graph
    T, e = G.all_transitions, G.edges
    settled = np.isfinite(study.rest).all(axis=1)
    U = np.concatenate([study.X, study.rest[settled], result.extra_states])
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
    active = ok & (np.linalg.norm(toward(w, p, periodic)[:, :m], axis=1) > tol)
    while active.any():
        k = np.flatnonzero(active)
        mid = w[k] + 0.5 * toward(w[k], p[k], periodic)
        r = F(mid[:, :m], mid[:, m:])
        start, stable, rest, lost = r.start.copy(), r.stable.copy(), r.rest_id.copy(), r.energy.copy()
        for i in np.flatnonzero((r.start_id != face[k]) & (r.start_id != other[k])):  # a neighbouring face: ask
            on = np.flatnonzero(r.face_ids[i] == face[k[i]])  # for the pair's own
            if not on.size:
                on = np.flatnonzero(r.face_ids[i] == other[k[i]])
            if not on.size:
                ok[k[i]] = False  # both faces are gone between partner and witness
                continue
            again = F(mid[i : i + 1, :m], r.faces[i][on[:1]])
            start[i], stable[i], rest[i], lost[i] = again.start[0], again.stable[0], again.rest_id[0], again.energy[0]
        here = ok[k]
        s = here & stable
        u = here & ~stable & (rest == rest_face[k])
        ok[k[here & ~s & ~u]] = False  # tips somewhere else: another transition lies between
        p[k[s], :m], p[k[s], m:] = mid[s, :m], start[s]
        w[k[u], :m], w[k[u], m:] = mid[u, :m], start[u]
        energy[k[u]] = lost[u]
        active = ok & (np.linalg.norm(toward(w, p, periodic)[:, :m], axis=1) > tol)
    best = np.full(G.n_edges, np.nan)
    pairs = np.zeros(G.n_edges, dtype=int)
    for n, (s_, d_) in enumerate(zip(e["src"], e["dst"])):
        sel = ok & (T["src"] == s_) & (T["dst"] == d_)
        pairs[n] = int(sel.sum())
        if pairs[n]:
            best[n] = float(energy[sel].min())
    return CrossingEnergies(energy=best, pairs=pairs, reported=np.asarray(e["energy"], float))
