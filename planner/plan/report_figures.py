"""The figures of the plan's report (:mod:`planner.plan.report`), one PNG each.

* the overview: runs per performance mode, the most frequent boundary types, and the
  sensitivity of the root scores to each parameter (dissertation Figures 4.23 and 4.24);
* per boundary pair (Figures 4.28-4.33): a map of both scenarios from their GeoJSON files
  (mission elements filled by kind, the two predicted tracks, launch and recovery) in local
  metres around the operational area; a parallel-coordinates plot of the two unit-cube rows
  over a strip of the parameters' sensitivity; and the dithering neighbourhood of each
  scenario on its two most sensitive coordinates, coloured by mode.

Each figure function writes its PNG (white, cropped tight) and closes the figure.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.artist import Artist
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from planner.common.html.figures import draw_area, label_map_axes, save_figure
from planner.common.html.text import EM_DASH, decimal
from sim.uuv.geo import LocalFrame

__all__ = [
    "MODE_LABELS",
    "MODE_COLOURS",
    "modes_figure",
    "boundary_types_figure",
    "sensitivity_figure",
    "pair_map_figure",
    "parallel_figure",
    "dithers_figure",
]

MODE_NAMES = ("TF", "SS", "MS", "TS")
MODE_LABELS = {"TF": "total failure", "SS": "safety success", "MS": "mission success", "TS": "total success"}
MODE_COLOURS = {"TF": "#d62728", "SS": "#ff7f0e", "MS": "#1f77b4", "TS": "#2ca02c", "invalid": "#9e9e9e"}
#: The two scenarios of a pair: track and parallel-coordinates colours.
SIDE_COLOURS = ("#6a3d9a", "#e6550d")
#: Map fill (face, edge, alpha) per GeoJSON ``kind``.
KIND_STYLE = {
    "operational_area": (None, "#333333", 1.0),
    "mission_area": ("#4daf4a", "#2b7a28", 0.35),
    "transmission": ("#377eb8", "#1f4e79", 0.30),
    "nogo": ("#e41a1c", "#a50f15", 0.40),
    "obstacle": ("#000000", "#000000", 0.75),
    "barrier": ("#000000", "#000000", 0.75),
}
KIND_LABELS = {
    "operational_area": "operational area",
    "mission_area": "mission area",
    "transmission": "transmission area",
    "nogo": "no-go area",
    "obstacle": "obstacle",
    "barrier": "barrier",
}
DPI = 100


def _save(fig, path: Path) -> None:
    save_figure(fig, path, dpi=DPI, bbox_inches="tight", facecolor="white")


# -- figures: overview ---------------------------------------------------------------------
def modes_figure(plan: dict, path: Path) -> None:
    """Runs of the study per performance mode, and the invalid scenarios (hatched)."""
    study = plan["study"]
    counts = study.get("modes", {}) or {}
    names = list(MODE_NAMES) + [m for m in counts if m not in MODE_NAMES]
    values = [int(counts.get(m, 0)) for m in names]
    colours = [MODE_COLOURS.get(m, "#555") for m in names]
    labels = [f"{m}\n{MODE_LABELS.get(m, '')}" for m in names]
    invalid = study.get("invalid_runs")
    if invalid is not None:
        names.append("invalid")
        values.append(int(invalid))
        colours.append(MODE_COLOURS["invalid"])
        labels.append("invalid\n(not run)")
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    bars = ax.bar(range(len(values)), values, color=colours, edgecolor="#333")
    if invalid is not None:
        bars[-1].set_hatch("//")
    total = max(sum(values), 1)
    for b, v in zip(bars, values):
        ax.annotate(
            f"{v:,}\n{100 * v / total:.0f}%",
            (b.get_x() + b.get_width() / 2, v),
            ha="center",
            va="bottom",
            fontsize=8,
            xytext=(0, 2),
            textcoords="offset points",
        )
    ax.set_xticks(range(len(values)), labels, fontsize=8)
    ax.set_ylabel("runs")
    ax.set_ylim(0, max(values + [1]) * 1.25)
    ax.set_title("Runs per performance mode")
    ax.spines[["top", "right"]].set_visible(False)
    _save(fig, path)


def _boundary_label(bt: dict) -> str:
    elements = " + ".join(str(e) for e in bt.get("elements", [])) or "?"
    return f"L{bt.get('level', '?')}: {elements}"


def boundary_types_figure(plan: dict, path: Path, top: int = 12) -> list[dict]:
    """The ``top`` boundary types with the most pairs; returns them."""
    types = [bt for bt in plan["study"].get("boundary_types", []) or [] if isinstance(bt, dict)]
    types = sorted(types, key=lambda bt: (-int(bt.get("pairs", 0)), float(bt.get("shortest", math.inf))))[:top]
    fig, ax = plt.subplots(figsize=(8.0, 0.9 + 0.32 * max(len(types), 1)))
    if types:
        labels = [_wrap(_boundary_label(bt), 60) for bt in types][::-1]
        values = [int(bt.get("pairs", 0)) for bt in types][::-1]
        levels = [int(bt.get("level", 0)) for bt in types][::-1]
        cmap = plt.get_cmap("tab10")
        ax.barh(range(len(values)), values, color=[cmap(lv % 10) for lv in levels], edgecolor="#333")
        ax.set_yticks(range(len(values)), labels, fontsize=8)
        for y, v in enumerate(values):
            ax.annotate(f"{v:,}", (v, y), va="center", fontsize=8, xytext=(3, 0), textcoords="offset points")
        ax.set_xlim(0, max(values) * 1.12)
        handles = [Patch(color=cmap(lv % 10), label=f"level {lv}") for lv in sorted(set(levels))]
        ax.legend(handles=handles, fontsize=8, loc="lower right")
    else:
        ax.text(0.5, 0.5, "no boundary pairs", ha="center", va="center", transform=ax.transAxes)
        ax.set_yticks([])
    ax.set_xlabel("boundary pairs")
    ax.set_title(f"Boundary types (top {top} by pairs)")
    ax.spines[["top", "right"]].set_visible(False)
    _save(fig, path)
    return types


def _wrap(text: str, width: int) -> str:
    if len(text) <= width:
        return text
    out, line = [], ""
    for word in text.split(" "):
        if line and len(line) + 1 + len(word) > width:
            out.append(line)
            line = word
        else:
            line = f"{line} {word}".strip()
    out.append(line)
    return "\n".join(out)


def sensitivity_figure(plan: dict, path: Path) -> list[str]:
    """Each parameter's importance for each root score; returns the roots drawn."""
    sens = {k: v for k, v in (plan.get("sensitivity") or {}).items() if isinstance(v, dict) and v}
    roots = list(sens) or ["mission_success"]
    n_params = max([len(v) for v in sens.values()] + [1])
    fig, axes = plt.subplots(1, len(roots), figsize=(5.2 * len(roots), 0.9 + 0.3 * n_params), squeeze=False)
    for ax, root in zip(axes[0], roots):
        imp = sens.get(root, {})
        if not imp:
            ax.text(0.5, 0.5, "no sensitivity", ha="center", va="center", transform=ax.transAxes)
            continue
        items = sorted(imp.items(), key=lambda kv: float(kv[1]))
        ax.barh(range(len(items)), [float(v) for _, v in items], color="#4c72b0", edgecolor="#333")
        ax.set_yticks(range(len(items)), [str(k) for k, _ in items], fontsize=8)
        ax.set_xlabel("importance")
        ax.set_title(root.replace("_", " "))
        ax.spines[["top", "right"]].set_visible(False)
    fig.suptitle("Sensitivity of the root scores to each parameter")
    fig.tight_layout()
    _save(fig, path)
    return list(sens)


# -- figures: one pair -----------------------------------------------------------------------
def _load_geojson(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and isinstance(data.get("features"), list) else None


def _local_frame(collections: Iterable[dict]) -> LocalFrame | None:
    """A local frame at the operational area's centre (else the mean of all coordinates)."""
    pts = []
    for fc in collections:
        for f in fc["features"]:
            geom = f.get("geometry") or {}
            if (f.get("properties") or {}).get("kind") == "operational_area" and geom.get("type") == "Polygon":
                ring = np.asarray(geom["coordinates"][0], dtype=float)
                lo, hi = ring.min(axis=0), ring.max(axis=0)
                return LocalFrame(float((lo[1] + hi[1]) / 2), float((lo[0] + hi[0]) / 2))
            pts += list(_flat_coordinates(geom))
    if not pts:
        return None
    c = np.mean(np.asarray(pts, dtype=float), axis=0)
    return LocalFrame(float(c[1]), float(c[0]))


def _flat_coordinates(geom: dict) -> Iterator[list[float]]:
    t = geom.get("type")
    if t == "Point":
        yield geom["coordinates"]
    elif t == "LineString":
        yield from geom["coordinates"]
    elif t == "Polygon":
        for ring in geom["coordinates"]:
            yield from ring


def _xy(frame: LocalFrame, coords) -> np.ndarray:
    a = np.asarray(coords, dtype=float).reshape(-1, 2)
    x, y = frame.to_local(a[:, 1], a[:, 0])
    return np.column_stack([np.atleast_1d(x), np.atleast_1d(y)])


def _draw_scenario(
    ax, fc: dict, frame: LocalFrame, colour: str, other: tuple[np.ndarray | None, str] | None
) -> np.ndarray | None:
    track = None
    kinds_seen = set()
    for f in fc["features"]:
        geom = f.get("geometry") or {}
        props = f.get("properties") or {}
        kind = str(props.get("kind", ""))
        if geom.get("type") == "Polygon":
            ring = _xy(frame, geom["coordinates"][0])
            face, edge, alpha = KIND_STYLE.get(kind, ("#999999", "#555555", 0.3))
            if face is None:
                draw_area(ax, ring, face=None, edge=edge, linewidth=1.5, linestyle="--")
            else:
                draw_area(ax, ring, face=face, edge=edge, alpha=alpha, linewidth=1)
            kinds_seen.add(kind)
            if kind != "operational_area" and props.get("name") not in (None, ""):
                c = ring[:-1].mean(axis=0) if len(ring) > 1 else ring[0]
                dark = kind in ("obstacle", "barrier")
                ax.annotate(
                    str(props["name"]),
                    c,
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if dark else "#111",
                    fontweight="bold" if dark else "normal",
                )
        elif geom.get("type") == "LineString" and kind == "predicted_track":
            track = _xy(frame, geom["coordinates"])
        elif geom.get("type") == "Point":
            p = _xy(frame, geom["coordinates"])[0]
            if kind == "launch":
                ax.plot(*p, marker="^", color="k", markersize=9, markerfacecolor="#ffd92f", zorder=6)
            elif kind == "recovery":
                ax.plot(*p, marker="s", color="k", markersize=8, markerfacecolor="#a6d854", zorder=6)
            elif kind == "waypoint":
                ax.plot(*p, marker="o", color="k", markersize=5, markerfacecolor="white", zorder=5)
                ax.annotate(f"wp{props.get('name', '')}", p, fontsize=7, xytext=(4, 4), textcoords="offset points")
    if other is not None and other[0] is not None:
        ax.plot(other[0][:, 0], other[0][:, 1], color=other[1], linewidth=1.0, linestyle=":", alpha=0.8, zorder=3)
    if track is not None:
        ax.plot(track[:, 0], track[:, 1], color=colour, linewidth=2.0, zorder=4)
        ax.plot(*track[-1], marker="x", color=colour, markersize=8, zorder=6)
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    label_map_axes(ax)
    ax.grid(True, alpha=0.3)
    return track


def pair_map_figure(pair: dict, scen: list[dict], out_dir: Path, path: Path) -> str | None:
    """Side-by-side maps of the pair's scenarios; returns a note when GeoJSON is missing."""
    fcs: list[dict] = []
    missing = []
    for s in scen:
        name = Path(str((s.get("files") or {}).get("geojson", f"{s['id']}.geojson"))).name
        fc = _load_geojson(out_dir / name)
        if fc is None:
            missing.append(name)
        else:
            fcs.append(fc)
    if missing or not fcs:
        return f"map not drawn: {', '.join(missing) or 'no scenarios'} not found in the plan directory"
    frame = _local_frame(fcs)
    if frame is None:
        return "map not drawn: the GeoJSON files hold no coordinates"
    tracks = []
    for fc in fcs:
        t = next(
            (
                f
                for f in fc["features"]
                if (f.get("properties") or {}).get("kind") == "predicted_track"
                and (f.get("geometry") or {}).get("type") == "LineString"
            ),
            None,
        )
        tracks.append(None if t is None else _xy(frame, t["geometry"]["coordinates"]))
    fig, axes = plt.subplots(1, len(fcs), figsize=(6.2 * len(fcs), 6.0), squeeze=False)
    for k, (ax, fc, s) in enumerate(zip(axes[0], fcs, scen)):
        other_k = 1 - k if len(fcs) == 2 else None
        other = None if other_k is None else (tracks[other_k], SIDE_COLOURS[other_k % 2])
        _draw_scenario(ax, fc, frame, SIDE_COLOURS[k % 2], other)
        mode = (s.get("predicted") or {}).get("mode", "?")
        ax.set_title(f"{s['id']}: predicted {mode} ({MODE_LABELS.get(mode, mode)})", color=SIDE_COLOURS[k % 2])
    present = {
        str((f.get("properties") or {}).get("kind"))
        for fc in fcs
        for f in fc["features"]
        if (f.get("geometry") or {}).get("type") == "Polygon"
    }
    handles: list[Artist] = [
        Patch(
            facecolor=KIND_STYLE[k][0] or "white",
            edgecolor=KIND_STYLE[k][1],
            alpha=max(KIND_STYLE[k][2], 0.5),
            label=KIND_LABELS[k],
            linestyle="--" if k == "operational_area" else "-",
        )
        for k in KIND_STYLE
        if k in present
    ]
    handles += [
        Line2D([], [], color=SIDE_COLOURS[k % 2], linewidth=2, label=f"{s['id']} predicted track")
        for k, s in enumerate(scen)
    ]
    handles += [
        Line2D([], [], marker="^", color="k", markerfacecolor="#ffd92f", linestyle="", label="launch"),
        Line2D([], [], marker="s", color="k", markerfacecolor="#a6d854", linestyle="", label="recovery"),
        Line2D([], [], marker="o", color="k", markerfacecolor="white", linestyle="", label="waypoint"),
        Line2D([], [], marker="x", color="#444", linestyle="", label="end of track"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=6, fontsize=8, frameon=False)
    fig.suptitle(f"Pair {pair.get('id')}: " + " + ".join(str(e) for e in pair.get("elements", [])))
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    _save(fig, path)
    return None


def parallel_figure(
    pair: dict, scen: list[dict], labels: list[str], owners: list[str], imp: tuple[np.ndarray, np.ndarray], path: Path
) -> None:
    """A pair's two unit-cube rows in parallel coordinates, over each coordinate's importance."""
    dim = len(labels)
    x = np.arange(dim)
    fig, (ax, axs) = plt.subplots(
        2,
        1,
        figsize=(max(7.0, 0.62 * dim + 2), 5.6),
        sharex=True,
        gridspec_kw={"height_ratios": [3, 1.1], "hspace": 0.06},
    )
    for xi in x:
        ax.axvline(xi, color="#bbbbbb", linewidth=0.8, zorder=0)
    # group the coordinates of one parameter (permutations) with a shaded band
    start = 0
    for i in range(1, dim + 1):
        if i == dim or owners[i] != owners[start]:
            if i - start > 1:
                ax.axvspan(start - 0.4, i - 1 + 0.4, color="#f0e6ff", zorder=0)
                axs.axvspan(start - 0.4, i - 1 + 0.4, color="#f0e6ff", zorder=0)
            start = i
    for k, s in enumerate(scen):
        u = np.asarray(s.get("u", []), dtype=float)
        if u.size != dim:
            continue
        mode = (s.get("predicted") or {}).get("mode", "?")
        ax.plot(
            x,
            u,
            color=SIDE_COLOURS[k % 2],
            linewidth=2,
            marker="o",
            markersize=5,
            label=f"{s['id']} (predicted {mode})",
        )
    ax.set_ylim(-0.03, 1.03)
    ax.set_ylabel("unit-cube value")
    ax.legend(fontsize=8, loc="upper right", ncol=2, framealpha=0.9)
    ax.set_title(
        f"Pair {pair.get('id')}: normalized parameters (distance {decimal(pair.get('distance'), missing=EM_DASH)})"
    )
    ms, ss = imp
    axs.bar(x, ms, color="#4c72b0", label="mission success", width=0.7)
    axs.bar(x, ss, bottom=ms, color="#dd8452", label="safety success", width=0.7)
    axs.set_ylabel("importance", fontsize=8)
    top = float(np.max(ms + ss)) if dim else 0.0
    axs.set_ylim(0, (top if top > 0 else 1.0) * 1.45)
    axs.legend(fontsize=7, loc="upper left", ncol=2, framealpha=0.9)
    axs.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
    axs.set_xlim(-0.5, dim - 0.5)
    axs.spines[["top", "right"]].set_visible(False)
    _save(fig, path)


def dithers_figure(
    pair: dict, scen: list[dict], dithers: dict, labels: list[str], axes_idx: tuple[int, int], path: Path
) -> bool:
    """Each side's dithers on two coordinates, coloured by mode; False when neither side was dithered."""
    present = [s for s in scen if s["id"] in dithers]
    if not present:
        return False
    i, j = axes_idx
    fig, axes = plt.subplots(1, len(present), figsize=(5.4 * len(present), 4.8), squeeze=False)
    for ax, s in zip(axes[0], present):
        U, modes = dithers[s["id"]]
        for code, name in [(-1, "invalid")] + list(enumerate(MODE_NAMES)):
            sel = modes == code
            if sel.any():
                ax.scatter(
                    U[sel, i],
                    U[sel, j],
                    s=14 if code >= 0 else 18,
                    marker="o" if code >= 0 else "x",
                    color=MODE_COLOURS[name],
                    alpha=0.75,
                    label=f"{name} ({int(sel.sum())})",
                    linewidths=1,
                )
        u = np.asarray(s.get("u", []), dtype=float)
        side = scen.index(s)
        if u.size == len(labels):
            ax.scatter(
                [u[i]],
                [u[j]],
                marker="*",
                s=260,
                color=SIDE_COLOURS[side % 2],
                edgecolor="k",
                zorder=5,
                label=f"{s['id']}",
            )
        mode = (s.get("predicted") or {}).get("mode", "?")
        ax.set_title(f"{s['id']} (predicted {mode}): {len(modes)} dithers", fontsize=10)
        ax.set_xlabel(labels[i])
        ax.set_ylabel(labels[j])
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7, loc="best", framealpha=0.9)
    fig.suptitle(f"Pair {pair.get('id')}: dithering neighbourhood on the two most sensitive coordinates")
    fig.tight_layout()
    _save(fig, path)
    return True
