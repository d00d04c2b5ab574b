"""A self-righting study's results on disk: ``graph.json``, ``graph.graphml``, ``states.png``, ``report.md``.

The JSON document (:func:`graph_document`) is the one record of the graph; GraphML and
the Markdown report are written from it, so they cannot disagree with it.
"""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from planner.selfright.analysis import SelfRightAnalysis
from planner.selfright.study import SelfRightStudy
from rapt.transitions import TransitionGraph

__all__ = ["graph_document", "write_graphml", "plot_states", "report_text", "write_outputs"]


def _state_degrees(study: SelfRightStudy, U: np.ndarray) -> dict:
    a = np.degrees(study.bounds[:, 0] + np.asarray(U, float) * np.ptp(study.bounds, axis=1))
    return {
        "joints_deg": [round(float(v), 3) for v in a[: study.n_free]],
        "body_deg": [round(float(v), 3) for v in a[study.n_free :]],
    }


def graph_document(study: SelfRightStudy, result: SelfRightAnalysis) -> dict:
    """The transition graph as plain JSON: nodes, one-way transitions, righting paths and the headline figures."""
    g: TransitionGraph = result.graph
    home = result.home
    cost = result.cost_to_home
    P = np.concatenate([study.X, study.rest[np.isfinite(study.rest).all(axis=1)], result.extra_states])
    nodes = []
    for n in range(g.n_nodes):
        members = np.flatnonzero(g.labels == n)
        rep = members[np.argmin(np.linalg.norm(g.points[members] - g.points[members].mean(axis=0), axis=1))]
        path = g.path(n, home) if home >= 0 and n != home else []
        nodes.append(
            {
                "id": n,
                "states": int(g.node_sizes[n]),
                "home": n == home,
                "can_right": bool(np.isfinite(cost[n])),
                "energy_to_home_J": None if not np.isfinite(cost[n]) else round(float(cost[n]), 4),
                "righting_path": [int(e) for e in path],
                "representative": _state_degrees(study, P[rep]),
            }
        )
    edges = []
    for e in range(g.n_edges):
        w = int(g.edges["witness"][e])
        edges.append(
            {
                "id": e,
                "source": int(g.edges["src"][e]),
                "target": int(g.edges["dst"][e]),
                "energy_J": round(float(g.edges["energy"][e]), 4),
                "boundary_pair_deg": round(float(np.degrees(g.edges["length"][e])), 4),
                "start": _state_degrees(study, study.X[w]),
                "rest": _state_degrees(study, study.rest[w]),
            }
        )
    return {
        "robot": study.robot.name,
        "slope_deg": study.slope,
        "method": study.method,
        "queries": study.queries,
        "known_states": result.n_known_states,
        "max_edge_deg": round(float(np.degrees(result.max_edge)), 4),
        "home_node": home,
        "self_rightable_fraction": round(result.rightable, 4),
        "mean_energy_to_home_J": None if not np.isfinite(result.energy_to_home) else round(result.energy_to_home, 4),
        "nodes": nodes,
        "edges": edges,
    }


def write_graphml(doc: dict, path: Path) -> None:
    """GraphML (yEd, Gephi, networkx.read_graphml) of the node graph, written with xml.etree."""
    ns = "http://graphml.graphdrawing.org/xmlns"
    root = ET.Element("graphml", xmlns=ns)
    keys = [
        ("states", "node", "int"),
        ("home", "node", "boolean"),
        ("can_right", "node", "boolean"),
        ("energy_to_home_J", "node", "double"),
        ("energy_J", "edge", "double"),
        ("boundary_pair_deg", "edge", "double"),
    ]
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


def plot_states(
    study: SelfRightStudy, result: SelfRightAnalysis, path: Path, grid: SelfRightStudy | None = None
) -> None:
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
    g = result.graph
    for ax, (i, j) in zip(axes.flat, pairs):
        if grid is not None:
            gd = np.degrees(grid.bounds[:, 0] + grid.X * np.ptp(grid.bounds, axis=1))
            ax.scatter(gd[:, i], gd[:, j], s=0.2, c="k", alpha=0.25, lw=0, label=f"{grid.method} ({grid.queries:,})")
        for mask, colour, label in ((study.stable, "tab:blue", "stable"), (~study.stable, "tab:red", "unstable")):
            ax.scatter(deg[mask, i], deg[mask, j], s=4, c=colour, lw=0, label=label)
        for w in g.edges["witness"]:
            if np.isfinite(rest[w]).all():
                ax.annotate(
                    "",
                    xy=(rest[w, i], rest[w, j]),
                    xytext=(deg[w, i], deg[w, j]),
                    arrowprops=dict(arrowstyle="->", color="m", lw=0.8),
                )
        ax.set_xlabel(f"{names[i]} (deg)")
        ax.set_ylabel(f"{names[j]} (deg)")
    for ax in list(axes.flat)[len(pairs) :]:
        ax.axis("off")
    axes.flat[0].legend(loc="upper right", fontsize=7, markerscale=3)
    fig.suptitle(
        f"{study.robot.name}, slope {study.slope:g}°: {study.queries:,} queries, "
        f"{g.n_nodes} nodes, {g.n_edges} transitions"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def report_text(study: SelfRightStudy, doc: dict) -> str:
    """``report.md``: the headline figures, then a table of the nodes and one of the transitions."""
    lines = [
        f"# Self-righting study: {doc['robot']}",
        "",
        f"{study.robot.description}".strip(),
        "",
        f"- ground slope: {doc['slope_deg']:g}°",
        f"- queries to the stability function: {doc['queries']:,} ({study.method}, {study.seconds:.1f} s)",
        f"- known states (every hull face of every queried joint state): {doc['known_states']:,}",
        f"- transition graph: {len(doc['nodes'])} nodes (stable regions), {len(doc['edges'])} one-way transitions "
        f"(Gabriel d_max {doc['max_edge_deg']:g}°)",
        f"- home node (upright, home joint angles): {doc['home_node']}",
        f"- self-rightable fraction of states: {doc['self_rightable_fraction']:.1%}",
        "- mean transition energy to reach home: "
        + ("n/a" if doc["mean_energy_to_home_J"] is None else f"{doc['mean_energy_to_home_J']:.2f} J"),
        "",
        "![state plot](states.png)",
        "",
        "## Nodes",
        "",
        "| node | states | can right | energy to home (J) | path (edges) | representative joints (deg) | body (deg) |",
        "|---:|---:|:---:|---:|---|---|---|",
    ]
    for n in doc["nodes"]:
        e = "-" if n["energy_to_home_J"] is None else f"{n['energy_to_home_J']:.2f}"
        lines.append(
            f"| {n['id']}{' (home)' if n['home'] else ''} | {n['states']:,} | {'yes' if n['can_right'] else 'no'} "
            f"| {e} | {' → '.join(map(str, n['righting_path'])) or '-'} | {n['representative']['joints_deg']} "
            f"| {n['representative']['body_deg']} |"
        )
    lines += [
        "",
        "## Transitions (lowest-energy witness per pair of nodes)",
        "",
        "| edge | from | to | energy (J) | boundary pair (deg) | joints at the tip (deg) | body start → rest (deg) |",
        "|---:|---:|---:|---:|---:|---|---|",
    ]
    for e in doc["edges"]:
        lines.append(
            f"| {e['id']} | {e['source']} | {e['target']} | {e['energy_J']:.2f} | {e['boundary_pair_deg']:.2f} "
            f"| {e['start']['joints_deg']} | {e['start']['body_deg']} → {e['rest']['body_deg']} |"
        )
    return "\n".join(lines) + "\n"


def write_outputs(study: SelfRightStudy, result: SelfRightAnalysis, out_dir: Path) -> dict:
    """Write the four files into ``out_dir`` (made if missing); returns the graph document."""
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = graph_document(study, result)
    (out_dir / "graph.json").write_text(json.dumps(doc, indent=1) + "\n")
    write_graphml(doc, out_dir / "graph.graphml")
    plot_states(study, result, out_dir / "states.png")
    (out_dir / "report.md").write_text(report_text(study, doc))
    return doc
