"""Which tipped-over states can a ground robot right itself from, and how (chapter 5).

Runs the manifold-constrained adaptive search (:mod:`rapt.manifold`) on the robot's
stability function (:mod:`sim.robots`), builds the transition graph
(:mod:`rapt.transitions`) and writes ``graph.json``, ``graph.graphml``, ``states.png``
(state plots like Figures 5.4 and 5.7) and ``report.md``.  ``rapt-plan selfright``
(:mod:`planner.cli.selfright`) and ``benchmarks/selfright.py`` (grid search included)
both drive these functions.

- :mod:`~planner.selfright.space`: the state space in radians and in the unit cube.
- :mod:`~planner.selfright.study`: :class:`SelfRightStudy`, the record of one search.
- :mod:`~planner.selfright.system`: the stability function as the searches see it.
- :mod:`~planner.selfright.search`: :func:`adaptive_study` (with :func:`refine_transitions`)
  and the :func:`grid_study` baseline.
- :mod:`~planner.selfright.graph`: Algorithm 8 on a study (:func:`build_graph`).
- :mod:`~planner.selfright.probes`: reference states that score graphs.
- :mod:`~planner.selfright.analysis`: :func:`analyse` and :func:`compare_graphs`.
- :mod:`~planner.selfright.crossing`: energies at the boundary itself.
- :mod:`~planner.selfright.export`: the files written for a study.
"""

from __future__ import annotations

from planner.selfright.analysis import GraphComparison, SelfRightAnalysis, analyse, compare_graphs, home_state
from planner.selfright.crossing import CrossingEnergies, crossing_energies
from planner.selfright.export import graph_document, plot_states, report_text, write_graphml, write_outputs
from planner.selfright.graph import StudyGraph, build_graph, default_max_edge, grid_connections
from planner.selfright.probes import Probes, probe_states
from planner.selfright.search import adaptive_study, grid_study, refine_transitions
from planner.selfright.space import space_bounds
from planner.selfright.study import SelfRightStudy

__all__ = [
    "SelfRightStudy",
    "space_bounds",
    "adaptive_study",
    "refine_transitions",
    "grid_study",
    "StudyGraph",
    "build_graph",
    "default_max_edge",
    "grid_connections",
    "Probes",
    "probe_states",
    "SelfRightAnalysis",
    "GraphComparison",
    "analyse",
    "compare_graphs",
    "home_state",
    "CrossingEnergies",
    "crossing_energies",
    "graph_document",
    "write_graphml",
    "plot_states",
    "report_text",
    "write_outputs",
]
