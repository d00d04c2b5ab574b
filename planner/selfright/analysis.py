"""What a self-righting study says: its transition graph, the chapter's figures of merit, graph against graph.

:func:`analyse` turns one :class:`~planner.selfright.study.SelfRightStudy` into a
:class:`SelfRightAnalysis` (the graph, the home node, who can right themselves and at
what cost); :func:`compare_graphs` decides whether two searches found the same graph,
which is how the adaptive search is judged against the grid.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from planner.selfright.graph import build_graph
from planner.selfright.probes import Probes, as_probes, probe_states
from planner.selfright.space import to_unit
from planner.selfright.study import SelfRightStudy
from rapt.transitions import TransitionGraph
from sim.robots import StabilityFunction

__all__ = ["SelfRightAnalysis", "GraphComparison", "analyse", "compare_graphs", "home_state"]


@dataclass(frozen=True)
class SelfRightAnalysis:
    """One study's transition graph and figures of merit (:func:`analyse`)."""

    graph: TransitionGraph
    home: int  # the home node (-1: the home state lies in no node)
    cost_to_home: np.ndarray  # (nodes,) lowest energy to reach home, inf where it cannot
    graph_seconds: float  # time to build the graph
    max_edge: float  # the Gabriel graph's d_max (embedded distance)
    extra_states: np.ndarray  # unit cube, in the graph's order (after the evaluated and resting states)
    probes: Probes  # the states the fractions below were scored on
    probe_rightable: np.ndarray  # (probes,) which of them reach home; compare_graphs reuses it for the same probes
    queries: int  # the study's queries to the stability function
    n_known_states: int  # every hull face of every evaluated joint state, each once
    rightable: float  # share of the probe states that reach home (NaN: no probes)
    energy_to_home: float  # mean energy to home of those that do (NaN: none)
    pair_length_deg: float  # mean boundary-pair length of the graph's edges, joint space (NaN: no edges)
    transition_energy: float  # mean energy of the graph's edges (NaN: no edges)

    @property
    def n_nodes(self) -> int:
        return self.graph.n_nodes

    @property
    def n_edges(self) -> int:
        return self.graph.n_edges


@dataclass(frozen=True)
class GraphComparison:
    """Graph ``a`` against graph ``b`` (:func:`compare_graphs`); pairs of figures are ``(a's, b's)``."""

    n_nodes: tuple[int, int]  # nodes holding at least ``min_share`` of the stable probes
    nodes_matched: int  # of those, nodes that map onto each other both ways
    n_edges: tuple[int, int]  # edges between those nodes (the lowest-energy one per pair of nodes)
    edges_matched: int  # edges present in both graphs
    same: bool  # every node and every edge matched
    rightable_agreement: float  # share of all probe states whose self-rightability agrees
    pair_length_deg: tuple[float, float]  # mean boundary-pair length over the matched edges
    transition_energy: tuple[float, float]  # mean transition energy over the matched edges
    matched_edges: np.ndarray  # (edges_matched, 2) indices into a's and b's edges


def home_state(study: SelfRightStudy, with_id: bool = False):
    """The upright home state: home joint angles, resting on the face below the base (unit cube); and its face id."""
    F = StabilityFunction(study.robot, study.slope)
    res = F(study.robot.home[None], np.zeros((1, F.n_body)))
    U = to_unit(np.concatenate([res.theta[0], res.start[0]]), study.bounds[:, 0], study.bounds[:, 1])
    return (U, int(res.start_id[0])) if with_id else U


def analyse(
    study: SelfRightStudy, *, max_edge: float | None = None, probes=None, use_ids: bool | None = None
) -> SelfRightAnalysis:
    """Transition graph (:func:`~planner.selfright.graph.build_graph`) and the chapter's figures of merit.

    ``probes`` (default: 500 random joint states, seed 0) are the states the
    self-rightable fraction is counted on; pass the same ones to compare studies.
    """
    t0 = time.perf_counter()
    graph, extra, max_edge, n_known = build_graph(study, max_edge=max_edge, use_ids=use_ids)
    seconds = time.perf_counter() - t0
    home_U, home_id = home_state(study, with_id=True)
    home = int(graph.node_of(study.embed(home_U[None]), ids=np.array([home_id]))[0])
    cost, _ = graph.costs_to(home) if home >= 0 else (np.full(graph.n_nodes, np.inf), None)
    probes = as_probes(probe_states(study.robot, study.slope, 500, 0) if probes is None else probes)
    if home >= 0:
        ok, energy = graph.outcome(study.embed(probes.U), home, ids=probes.ids)
    else:  # no home node: nothing rights itself
        ok, energy = np.zeros(len(probes), bool), np.zeros(len(probes))
    e = graph.edges
    return SelfRightAnalysis(
        graph=graph,
        home=home,
        cost_to_home=cost,
        graph_seconds=seconds,
        max_edge=max_edge,
        extra_states=extra,
        probes=probes,
        probe_rightable=ok,
        queries=study.queries,
        n_known_states=n_known,
        rightable=float(ok.mean()) if len(probes) else float("nan"),
        energy_to_home=float(energy[ok].mean()) if ok.any() else float("nan"),
        pair_length_deg=float(np.degrees(e["length"]).mean()) if graph.n_edges else float("nan"),
        transition_energy=float(e["energy"].mean()) if graph.n_edges else float("nan"),
    )


def _rightable(result: SelfRightAnalysis, study: SelfRightStudy, probes: Probes) -> np.ndarray:
    """Which probe states can reach the home node: :func:`analyse`'s own answer when it scored these probes."""
    if result.probes is probes:
        return result.probe_rightable
    if result.home < 0:
        return np.zeros(len(probes), dtype=bool)
    return result.graph.outcome(study.embed(probes.U), result.home, ids=probes.ids)[0]


def _node_map(src: np.ndarray, dst: np.ndarray, keep: set) -> dict:
    """Each node of ``keep`` → the node its probes fall in most on the other side (-1: none)."""
    out = {}
    for n in keep:
        d = dst[(src == n) & (dst >= 0)]
        out[n] = int(np.bincount(d).argmax()) if d.size else -1
    return out


def _edge_set(g: TransitionGraph, keep: set, remap: dict | None = None) -> dict:
    """{(src, dst): (energy, boundary-pair length, edge index)}, the lowest-energy edge per mapped pair."""
    es: dict = {}
    for k, (s, d, e, L) in enumerate(zip(g.edges["src"], g.edges["dst"], g.edges["energy"], g.edges["length"])):
        if s in keep and d in keep:
            key = (remap[s], remap[d]) if remap else (int(s), int(d))
            if key not in es or e < es[key][0]:
                es[key] = (float(e), float(L), k)
    return es


def _mean(v: np.ndarray) -> float:
    return float(v.mean()) if v.size else float("nan")


def compare_graphs(
    a: SelfRightAnalysis,
    study_a: SelfRightStudy,
    b: SelfRightAnalysis,
    study_b: SelfRightStudy,
    probes,
    min_share: float = 0.01,
) -> GraphComparison:
    """Is graph ``a`` the same as ``b``?  Judged on probe states, since node numbers are arbitrary.

    Each truly stable probe state falls in one node of each graph (through its nearest
    known stable state on the same hull face); a node of ``a`` maps to the node of ``b``
    most of its probes fall in.  Nodes holding fewer than ``min_share`` of the stable
    probes are ignored.  Reports nodes and edges matched both ways, and the share of all
    probe states whose self-rightability agrees, and — over the edges matched in both
    graphs — the mean boundary-pair length and transition energy of each, and which edge of
    each they are.
    """
    probes = as_probes(probes)
    ga, gb = a.graph, b.graph
    st = probes.stable
    pid = None if probes.ids is None else probes.ids[st]
    na = ga.node_of(study_a.embed(probes.U[st]), ids=pid)
    nb = gb.node_of(study_b.embed(probes.U[st]), ids=pid)

    def big(nodes, n):
        share = np.bincount(nodes[nodes >= 0], minlength=n) / len(nodes)
        return set(np.flatnonzero(share >= min_share).tolist())

    big_a, big_b = big(na, ga.n_nodes), big(nb, gb.n_nodes)
    ab, ba = _node_map(na, nb, big_a), _node_map(nb, na, big_b)
    nodes_matched = sum(1 for n, m in ab.items() if ba.get(m) == n)
    ea, eb = _edge_set(ga, big_a, ab), _edge_set(gb, big_b)
    both = sorted(set(ea) & set(eb))
    pair = np.array([[ea[k][1], eb[k][1]] for k in both]).reshape(-1, 2)
    energy = np.array([[ea[k][0], eb[k][0]] for k in both]).reshape(-1, 2)
    ra, rb = (_rightable(r, study, probes) for r, study in ((a, study_a), (b, study_b)))
    return GraphComparison(
        n_nodes=(len(big_a), len(big_b)),
        nodes_matched=nodes_matched,
        n_edges=(len(ea), len(eb)),
        edges_matched=len(both),
        same=nodes_matched == len(big_a) == len(big_b) and set(ea) == set(eb),
        rightable_agreement=float((ra == rb).mean()),
        # on the matched edges (the same transitions in both graphs): a's and b's means
        pair_length_deg=(_mean(np.degrees(pair[:, 0])), _mean(np.degrees(pair[:, 1]))),
        transition_energy=(_mean(energy[:, 0]), _mean(energy[:, 1])),
        matched_edges=np.array([[ea[k][2], eb[k][2]] for k in both], dtype=int).reshape(-1, 2),
    )
