"""The HTML report of a field plan: what the test engineers read before going on the water.

:func:`write_report` turns a ``rapt.plan/1`` plan (:func:`planner.plan.generate.generate`) into
``report.html`` plus PNG figures in ``figures/``, beside the plan's scenario files:

* a header: mission, budget, seed, valid and invalid runs;
* performance modes and boundary types (dissertation Figure 4.23): runs per mode and the
  most frequent boundary types (level and score elements that flip);
* sensitivity (Figure 4.24): the importance of each parameter for each root score;
* per boundary pair (Figures 4.28-4.33): a map of both scenarios (mission elements filled
  by kind, the two predicted tracks, launch and recovery) in local metres around the
  operational area; a parallel-coordinates plot of the two unit-cube rows over a strip of
  the parameters' sensitivity; with ``dithers``, the dithering neighbourhood of each
  scenario on its two most sensitive coordinates, coloured by mode; and a table of the
  predicted mode, how often dithering reproduced it, the nearest other mode and the
  sub-boundaries nearby (orthogonal or parallel);
* the run order, with links to each scenario's ``.plan``, ``.waypoints`` and ``.geojson``.

The page is one self-contained file: inline CSS, relative ``<img>`` links, no JavaScript
and nothing fetched from the network, so it opens from a laptop on the range.  Every text
taken from the plan or the mission is HTML-escaped.
"""

from __future__ import annotations

import html
import json
import math
import re
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import quote

import matplotlib

matplotlib.use("Agg")  # files only: no display on CI machines or range laptops

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.artist import Artist  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.patches import Polygon as MplPolygon  # noqa: E402

from planner.common.plans import PLAN_SCHEMA  # noqa: E402
from rapt.errors import InputError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402

__all__ = ["write_report", "REPORT_NAME", "FIGURES_DIR"]

REPORT_NAME = "report.html"
FIGURES_DIR = "figures"

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

_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 0; color: #222;
       background: #fff; line-height: 1.4; }
header { background: #1f3b57; color: #fff; padding: 16px 28px; }
header h1 { margin: 0 0 6px 0; font-size: 1.6em; }
header dl { display: flex; flex-wrap: wrap; gap: 6px 28px; margin: 0; }
header dt { font-weight: 600; opacity: .8; }
header dd { margin: 0 0 0 6px; }
header .item { display: flex; }
main { padding: 8px 28px 40px 28px; max-width: 1400px; }
h2 { border-bottom: 2px solid #1f3b57; padding-bottom: 4px; margin-top: 32px; }
h3 { margin-bottom: 4px; }
figure { margin: 10px 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: .9em; color: #555; }
.row { display: flex; flex-wrap: wrap; gap: 16px; align-items: flex-start; }
table { border-collapse: collapse; margin: 8px 0; font-size: .92em; }
th, td { border: 1px solid #ccc; padding: 3px 8px; text-align: left; vertical-align: top; }
th { background: #eef2f6; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.mode { display: inline-block; padding: 0 6px; border-radius: 3px; color: #fff; font-weight: 600; }
.note { color: #8a4b00; }
.muted { color: #777; }
section.pair { border-top: 1px solid #ccc; margin-top: 24px; }
details { margin: 6px 0; }
summary { cursor: pointer; }
"""


# -- helpers ------------------------------------------------------------------------------
def _e(value: Any) -> str:
    return html.escape(str(value), quote=True)


def _num(value: Any, digits: int = 3) -> str:
    if value is None:
        return "—"
    try:
        v = float(value)
    except (TypeError, ValueError):
        return _e(value)
    if not math.isfinite(v):
        return "—"
    if v == int(v) and abs(v) < 1e12 and isinstance(value, (int, np.integer)):
        return f"{int(v):,}"
    return f"{v:.{digits}g}" if abs(v) >= 1e4 or (v != 0 and abs(v) < 1e-3) else f"{v:.{digits}f}"


def _pct(value: Any) -> str:
    if value is None:
        return "—"
    return f"{100.0 * float(value):.0f}%"


def _mode_badge(mode: Any) -> str:
    colour = MODE_COLOURS.get(str(mode), "#555")
    title = MODE_LABELS.get(str(mode), str(mode))
    return f'<span class="mode" style="background:{colour}" title="{_e(title)}">{_e(mode)}</span>'


def _slug(text: Any) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", str(text)).strip("_") or "x"


def _save(fig, path: Path) -> None:
    try:
        fig.savefig(path, dpi=DPI, bbox_inches="tight", facecolor="white")
    finally:
        plt.close(fig)


def _check_plan(plan: Any) -> None:
    if not isinstance(plan, dict):
        raise InputError(f"plan: expected a {PLAN_SCHEMA} plan (a dict from plan.json), got {type(plan).__name__}")
    schema = plan.get("schema")
    if schema != PLAN_SCHEMA:
        raise InputError(f"plan: expected schema {PLAN_SCHEMA!r}, got {schema!r}")
    missing = [k for k in ("mission", "study", "sensitivity", "pairs", "scenarios", "run_order") if k not in plan]
    if missing:
        raise InputError(f"plan: a {PLAN_SCHEMA} plan needs {', '.join(missing)}")


def _check_dithers(dithers: Any, dim: int) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    if dithers is None:
        return {}
    if not isinstance(dithers, dict):
        raise InputError(f"dithers: expected a dict of scenario id -> (U, modes), got {type(dithers).__name__}")
    out = {}
    for sid, value in dithers.items():
        try:
            U, modes = value
        except (TypeError, ValueError):
            raise InputError(f"dithers[{sid!r}]: expected a pair (U, modes)") from None
        U = np.asarray(U, dtype=float)
        modes = np.asarray(modes).astype(int)
        if U.ndim != 2 or U.shape[1] != dim or modes.shape != (U.shape[0],):
            raise InputError(
                f"dithers[{sid!r}]: expected U of shape (n, {dim}) and modes of shape (n,), "
                f"got {U.shape} and {modes.shape}"
            )
        out[str(sid)] = (U, modes)
    return out


# -- coordinates of the unit cube -----------------------------------------------------------
def _coordinates(plan: dict) -> tuple[list[str], list[str]]:
    """(label, parameter name) of every unit-cube coordinate.

    A permutation of n items takes n coordinates, one random key per item; its items (in
    declaration order) are recovered from any scenario: the item of rank r is ``value[r]``
    and has the r-th smallest key.
    """
    mission = plan["mission"]
    dim = int(mission.get("dim", 0))
    names = [str(n) for n in mission.get("parameters", [])]
    scen = plan["scenarios"][0] if plan["scenarios"] else None
    labels: list[str] = []
    owners: list[str] = []
    if scen is not None and isinstance(scen.get("parameters"), dict):
        values = scen["parameters"]
        u = np.asarray(scen.get("u", []), dtype=float)
        start = 0
        for name in names:
            v = values.get(name)
            if isinstance(v, (list, tuple)) and len(v) > 1:
                width = len(v)
                items = [str(i) for i in range(width)]
                keys = u[start : start + width]
                if keys.size == width:
                    for rank, k in enumerate(np.argsort(keys, kind="stable")):
                        items[int(k)] = str(v[rank])
                labels += [f"{name}[{it}]" for it in items]
                owners += [name] * width
            else:
                labels.append(name)
                owners.append(name)
            start += 1 if not (isinstance(v, (list, tuple)) and len(v) > 1) else len(v)
    if len(labels) != dim:
        if len(names) == dim:
            labels, owners = list(names), list(names)
        else:
            labels = [f"u{i}" for i in range(dim)]
            owners = labels[:]
    return labels, owners


def _coordinate_importance(plan: dict, owners: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate importance for mission and safety success (a parameter's share split evenly)."""
    width = {o: owners.count(o) for o in owners}
    sens = plan.get("sensitivity", {})
    rows = []
    for root in ("mission_success", "safety_success"):
        imp = sens.get(root, {}) or {}
        rows.append(np.array([float(imp.get(o, 0.0)) / width[o] for o in owners]))
    return rows[0], rows[1]


# -- figures: overview ---------------------------------------------------------------------
def _fig_modes(plan: dict, path: Path) -> None:
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


def _fig_boundary_types(plan: dict, path: Path, top: int = 12) -> list[dict]:
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


def _fig_sensitivity(plan: dict, path: Path) -> list[str]:
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
                ax.add_patch(MplPolygon(ring, closed=True, fill=False, edgecolor=edge, linewidth=1.5, linestyle="--"))
            else:
                ax.add_patch(MplPolygon(ring, closed=True, facecolor=face, edgecolor=edge, alpha=alpha, linewidth=1))
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
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.grid(True, alpha=0.3)
    return track


def _fig_map(pair: dict, scen: list[dict], out_dir: Path, path: Path) -> str | None:
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


def _fig_parallel(
    pair: dict, scen: list[dict], labels: list[str], owners: list[str], imp: tuple[np.ndarray, np.ndarray], path: Path
) -> None:
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
    ax.set_title(f"Pair {pair.get('id')}: normalized parameters (distance {_num(pair.get('distance'))})")
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


def _fig_dithers(
    pair: dict, scen: list[dict], dithers: dict, labels: list[str], axes_idx: tuple[int, int], path: Path
) -> bool:
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


# -- HTML ----------------------------------------------------------------------------------------
def _img(src: str, alt: str, caption: str) -> str:
    return f'<figure><img src="{_e(quote(src))}" alt="{_e(alt)}"><figcaption>{_e(caption)}</figcaption></figure>'


def _header(plan: dict) -> str:
    m, st = plan["mission"], plan["study"]
    items = [
        ("mission", m.get("name", "?")),
        ("file", m.get("file", "?")),
        ("dimensions", m.get("dim", "?")),
        ("budget", _num(st.get("budget"))),
        ("seed", st.get("seed", "?")),
        ("valid runs", _num(st.get("valid_runs"))),
        ("invalid runs", _num(st.get("invalid_runs"))),
        ("pairs", len(plan["pairs"])),
        ("scenarios", len(plan["scenarios"])),
    ]
    dl = "".join(f'<div class="item"><dt>{_e(k)}</dt><dd>{_e(v)}</dd></div>' for k, v in items)
    return f"<header><h1>Field-test plan: {_e(m.get('name', '?'))}</h1><dl>{dl}</dl></header>"


def _summary_table(plan: dict) -> str:
    """Per pair: distance, P(predicted outcome) of each side and of its variant, and the verdict."""
    dith = (plan.get("study") or {}).get("dithering") or {}
    noise = ", ".join(f"{_e(k)} {_num(v)}" for k, v in (dith.get("expected") or {}).items()) or "—"
    head = (
        "<tr><th>pair</th><th>sub-boundary</th><th>modes</th><th>distance</th><th>P a / b</th>"
        "<th>variant P a / b</th><th>verdict</th></tr>"
    )
    rows = []
    for p in plan["pairs"]:
        probs = p.get("p_predicted") or [None, None]
        var = p.get("variant_p_predicted") or [None, None]
        verdict = p.get("verdict", "—")
        reason = f'<br><span class="note">{_e(p["reason"])}</span>' if p.get("reason") else ""
        rows.append(
            f"<tr><td class='num'>{_e(p['id'])}</td><td>{_e(', '.join(p['elements']))}</td>"
            f"<td>{' / '.join(_mode_badge(m) for m in p['modes'])}</td><td class='num'>{_num(p['distance'], 3)}</td>"
            f"<td class='num'>{_pct(probs[0])} / {_pct(probs[1])}</td>"
            f"<td class='num'>{_pct(var[0])} / {_pct(var[1])}</td><td>{_e(verdict)}{reason}</td></tr>"
        )
    note = (
        f"<p class=\"muted\">P: share of dithers that show the side's predicted outcome (mode and the pair's "
        f"elements) under the expected execution noise ({noise}); a side needs {_pct(dith.get('target'))}.</p>"
    )
    return f"<table>{head}{''.join(rows)}</table>{note}"


def _scenario_table(scen: list[dict]) -> str:
    head = (
        "<tr><th>scenario</th><th>predicted mode</th><th>P(predicted mode)</th><th>dithering runs "
        "(valid / all)</th><th>modes seen</th><th>nearest other mode</th><th>sub-boundaries nearby</th></tr>"
    )
    rows = []
    for s in scen:
        d = s.get("dithering") or {}
        mode = (s.get("predicted") or {}).get("mode", "?")
        seen = ", ".join(f"{_e(k)} {_e(v)}" for k, v in (d.get("modes") or {}).items()) or "—"
        subs = d.get("sub_boundaries") or []
        if subs:
            sub_html = "<br>".join(
                f"{_e(b.get('element', '?'))} <em>({_e(b.get('relation', '?'))})</em>: "
                f"{_pct(b.get('share'))} of runs, nearest {_num(b.get('nearest'))}"
                for b in subs
            )
        elif d:
            sub_html = "none found"
        else:
            sub_html = "—"
        runs = f"{_e(d.get('valid', '—'))} / {_e(d.get('runs', '—'))}" if d else "not dithered"
        p = d.get("p_predicted_mode")
        warn = ' <span class="note">(fragile)</span>' if p is not None and float(p) < 0.6 else ""
        rows.append(
            f"<tr><td>{_e(s['id'])}</td><td>{_mode_badge(mode)} {_e(MODE_LABELS.get(mode, ''))}</td>"
            f"<td class='num'>{_pct(p)}{warn}</td><td class='num'>{runs}</td><td>{seen}</td>"
            f"<td class='num'>{_num(d.get('nearest_other_mode'))}</td><td>{sub_html}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def _parameter_table(scen: list[dict]) -> str:
    names: list[str] = []
    for s in scen:
        for n in s.get("parameters") or {}:
            if n not in names:
                names.append(n)
    head = "<tr><th>parameter</th>" + "".join(f"<th>{_e(s['id'])}</th>" for s in scen) + "</tr>"

    def cell(v):
        if isinstance(v, (list, tuple)):
            return _e(" → ".join(str(x) for x in v))
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return _num(v, 4)
        return _e(v)

    rows = "".join(
        f"<tr><td>{_e(n)}</td>"
        + "".join(f"<td class='num'>{cell((s.get('parameters') or {}).get(n))}</td>" for s in scen)
        + "</tr>"
        for n in names
    )
    return f"<details><summary>Parameter values</summary><table>{head}{rows}</table></details>"


def _run_order_table(plan: dict, out_dir: Path) -> str:
    by_id = {s["id"]: s for s in plan["scenarios"]}
    pair_of = {sid: p.get("id") for p in plan["pairs"] for sid in p.get("scenarios", [])}
    head = "<tr><th>#</th><th>scenario</th><th>pair</th><th>predicted mode</th><th>P(predicted mode)</th><th>files</th></tr>"
    rows = []
    for n, sid in enumerate(plan["run_order"], start=1):
        s = by_id.get(sid, {"id": sid})
        links = []
        for kind in ("plan", "waypoints", "geojson"):
            name = (s.get("files") or {}).get(kind)
            if not name:
                continue
            name = Path(str(name)).name
            if (out_dir / name).is_file():
                links.append(f'<a href="{_e(quote(name))}">{_e(name)}</a>')
            else:
                links.append(f'<span class="muted">{_e(name)} (missing)</span>')
        mode = (s.get("predicted") or {}).get("mode", "?")
        p = (s.get("dithering") or {}).get("p_predicted_mode")
        rows.append(
            f"<tr><td class='num'>{n}</td><td>{_e(sid)}</td><td>{_e(pair_of.get(sid, '—'))}</td>"
            f"<td>{_mode_badge(mode)}</td><td class='num'>{_pct(p)}</td><td>{' · '.join(links) or '—'}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


class _Figures(NamedTuple):
    """What every pair's figures share: coordinate labels and owners, importances and the dithering axes."""

    labels: list[str]
    owners: list[str]
    importance: tuple[np.ndarray, np.ndarray]
    axes: tuple[int, int]
    dim: int


def _pair_section(
    pair: dict,
    by_id: dict[str, dict],
    out_dir: Path,
    fig_dir: Path,
    figures: _Figures,
    dithers: dict[str, tuple[np.ndarray, np.ndarray]],
) -> list[str]:
    """One boundary pair's section: its map, parallel coordinates, dithering plot and tables."""
    labels, owners, imp, axes_idx, dim = figures
    body: list[str] = []
    pid = _slug(pair.get("id"))
    scen = [by_id[sid] for sid in pair.get("scenarios", []) if sid in by_id]
    modes = pair.get("modes", [])
    elements = ", ".join(str(e) for e in pair.get("elements", []))
    body.append(f'<section class="pair" id="pair-{_e(pid)}"><h3>Pair {_e(pair.get("id"))}: {_e(elements)}</h3>')
    body.append(
        f"<p>Score-tree level {_e(pair.get('level', '?'))}; modes "
        + " / ".join(_mode_badge(m) for m in modes)
        + f"; distance in the unit cube {_num(pair.get('distance'))}; scenarios "
        + ", ".join(_e(s["id"]) for s in scen)
        + ".</p>"
    )
    if not scen:
        body.append('<p class="note">The pair\'s scenarios are missing from the plan.</p></section>')
        return body
    note = _fig_map(pair, scen, out_dir, fig_dir / f"pair{pid}_map.png")
    if note is None:
        body.append(
            _img(
                f"{FIGURES_DIR}/pair{pid}_map.png",
                f"map of pair {pair.get('id')}",
                "Mission elements of each scenario in metres east/north of the operational area's "
                "centre, its predicted track (solid) and the other scenario's track (dotted).",
            )
        )
    else:
        body.append(f'<p class="note">{_e(note)}</p>')
    _fig_parallel(pair, scen, labels, owners, imp, fig_dir / f"pair{pid}_parallel.png")
    body.append(
        _img(
            f"{FIGURES_DIR}/pair{pid}_parallel.png",
            f"parallel coordinates of pair {pair.get('id')}",
            "Unit-cube coordinates of both scenarios (a permutation spans several shaded "
            "coordinates, one key per item); below, each coordinate's importance for mission "
            "and safety success.",
        )
    )
    if dim >= 2 and _fig_dithers(pair, scen, dithers, labels, axes_idx, fig_dir / f"pair{pid}_dithers.png"):
        body.append(
            _img(
                f"{FIGURES_DIR}/pair{pid}_dithers.png",
                f"dithering of pair {pair.get('id')}",
                f"Dithering runs around each scenario on {labels[axes_idx[0]]} and "
                f"{labels[axes_idx[1]]} (the two most sensitive coordinates), coloured by the mode "
                "the stochastic simulation gave; the star is the scenario.",
            )
        )
    body.append(_scenario_table(scen))
    body.append(_parameter_table(scen))
    body.append("</section>")
    return body


def write_report(plan: dict, out_dir: Path, dithers: dict[str, tuple[np.ndarray, np.ndarray]] | None = None) -> Path:
    """Write ``out_dir/report.html`` and its figures (``out_dir/figures/*.png``); return the page's path.

    ``plan`` is a ``rapt.plan/1`` plan (as :func:`planner.plan.generate.generate` returns it or
    ``plan.json`` holds); its scenario files are read from ``out_dir``.  ``dithers`` maps a
    scenario id to ``(U, modes)`` of its dithering runs: unit-cube rows (n, dim) and modes
    0..3 (TF, SS, MS, TS) or -1 (invalid); without it the dithering plots are left out.
    """
    _check_plan(plan)
    dim = int(plan["mission"].get("dim", 0))
    dithers = _check_dithers(dithers, dim)
    out_dir = Path(out_dir)
    fig_dir = out_dir / FIGURES_DIR
    fig_dir.mkdir(parents=True, exist_ok=True)
    labels, owners = _coordinates(plan)
    imp = _coordinate_importance(plan, owners)
    total_imp = imp[0] + imp[1]
    order = np.argsort(-total_imp, kind="stable")
    axes_idx = (int(order[0]), int(order[1])) if dim >= 2 else (0, 0)

    body = [_header(plan), "<main>", "<h2>Summary</h2>", _summary_table(plan)]
    # overview
    _fig_modes(plan, fig_dir / "modes.png")
    top = _fig_boundary_types(plan, fig_dir / "boundary_types.png")
    body.append("<h2>Performance modes and boundary types</h2>")
    body.append(
        '<div class="row">'
        + _img(
            f"{FIGURES_DIR}/modes.png",
            "runs per performance mode",
            "Runs of the study per performance mode, and the invalid scenarios (hatched); percentages of all runs.",
        )
        + _img(
            f"{FIGURES_DIR}/boundary_types.png",
            "boundary types",
            f"The {len(top)} most frequent boundary types: score-tree level and the elements that "
            "flip across a boundary pair.",
        )
        + "</div>"
    )
    # sensitivity
    roots = _fig_sensitivity(plan, fig_dir / "sensitivity.png")
    body.append("<h2>Sensitivity</h2>")
    body.append(
        _img(
            f"{FIGURES_DIR}/sensitivity.png",
            "sensitivity",
            "Estimated importance of each parameter for " + (", ".join(roots) or "the root scores") + ".",
        )
    )
    # pairs
    by_id = {s["id"]: s for s in plan["scenarios"]}
    body.append("<h2>Boundary pairs</h2>")
    if not plan["pairs"]:
        body.append('<p class="note">The plan holds no boundary pairs.</p>')
    figures = _Figures(labels, owners, imp, axes_idx, dim)
    for pair in plan["pairs"]:
        body.extend(_pair_section(pair, by_id, out_dir, fig_dir, figures, dithers))
    # run order
    body.append("<h2>Run order</h2>")
    body.append(_run_order_table(plan, out_dir))
    body.append(
        '<p class="muted">Generated by RAPT from <a href="plan.json">plan.json</a> '
        f"(schema {_e(PLAN_SCHEMA)}).</p></main>"
    )
    title = f"RAPT field plan: {plan['mission'].get('name', '?')}"
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width, initial-scale=1"><title>{_e(title)}</title>'
        f"<style>{_CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
    path = out_dir / REPORT_NAME
    path.write_text(page, encoding="utf-8")
    return path
