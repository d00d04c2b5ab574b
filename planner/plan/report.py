"""The HTML report of a field plan: what the test engineers read before going on the water.

:func:`write_report` turns a field plan (:func:`planner.plan.generate.generate`, schema
:data:`~planner.common.plans.PLAN_SCHEMA`) into
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
taken from the plan or the mission is HTML-escaped.  This module writes the page; the
figures are :mod:`planner.plan.report_figures`', the escaping and number formats
:mod:`planner.common.html.text`'s.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, NamedTuple
from urllib.parse import quote

import numpy as np

from planner.common.atomic import write_text_atomic
from planner.common.html.text import EM_DASH, decimal, escape, percent
from planner.common.plans import PLAN_SCHEMA
from planner.plan.pair_shifts import shift_note
from planner.plan.planned_for import summary_lines
from planner.plan.report_figures import (
    MODE_COLOURS,
    MODE_LABELS,
    boundary_types_figure,
    dithers_figure,
    modes_figure,
    pair_map_figure,
    parallel_figure,
    sensitivity_figure,
)
from planner.plan.unreached import unreached_line
from rapt.errors import InputError

__all__ = ["write_report", "REPORT_NAME", "FIGURES_DIR"]

REPORT_NAME = "report.html"
FIGURES_DIR = "figures"
#: A missing value (the comparison's report writes an en dash).
MISSING = EM_DASH

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


def _mode_badge(mode: Any) -> str:
    colour = MODE_COLOURS.get(str(mode), "#555")
    title = MODE_LABELS.get(str(mode), str(mode))
    return f'<span class="mode" style="background:{colour}" title="{escape(title)}">{escape(mode)}</span>'


def _slug(text: Any) -> str:
    return re.sub(r"[^A-Za-z0-9_-]+", "_", str(text)).strip("_") or "x"


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


# -- HTML ----------------------------------------------------------------------------------------
def _img(src: str, alt: str, caption: str) -> str:
    return f'<figure><img src="{escape(quote(src))}" alt="{escape(alt)}"><figcaption>{escape(caption)}</figcaption></figure>'


def _header(plan: dict) -> str:
    m, st = plan["mission"], plan["study"]
    items = [
        ("mission", m.get("name", "?")),
        ("file", m.get("file", "?")),
        ("dimensions", m.get("dim", "?")),
        ("budget", decimal(st.get("budget"), missing=MISSING)),
        ("seed", st.get("seed", "?")),
        ("valid runs", decimal(st.get("valid_runs"), missing=MISSING)),
        ("invalid runs", decimal(st.get("invalid_runs"), missing=MISSING)),
        ("pairs", len(plan["pairs"])),
        ("scenarios", len(plan["scenarios"])),
    ]
    dl = "".join(f'<div class="item"><dt>{escape(k)}</dt><dd>{escape(v)}</dd></div>' for k, v in items)
    day = "".join(f"<p>{escape(line)}</p>" for line in summary_lines(m.get("planned_for")))
    cannot = unreached_line(st.get("unreached"))
    if cannot is not None:
        day += f'<p class="unreached">{escape(cannot)}</p>'
    return f"<header><h1>Field-test plan: {escape(m.get('name', '?'))}</h1><dl>{dl}</dl>{day}</header>"


def _summary_table(plan: dict) -> str:
    """Per pair: distance, P(predicted outcome) of each side and of its flown variant, P(straddle), the verdict."""
    dith = (plan.get("study") or {}).get("dithering") or {}
    noise = (
        ", ".join(f"{escape(k)} {decimal(v, missing=MISSING)}" for k, v in (dith.get("expected") or {}).items())
        or MISSING
    )
    head = (
        "<tr><th>pair</th><th>sub-boundary</th><th>modes</th><th>distance</th><th>P a / b</th>"
        "<th>variant P a / b</th><th>P straddle</th><th>verdict</th></tr>"
    )
    rows = []
    for p in plan["pairs"]:
        probs = p.get("p_predicted") or [None, None]
        var = p.get("variant_p_predicted") or [None, None]
        verdict = p.get("verdict", MISSING)
        notes = [p["reason"]] if p.get("reason") else []
        notes += [shift_note(p["shifted"])] if p.get("shifted") else []
        reason = "".join(f'<br><span class="note">{escape(n)}</span>' for n in notes)
        rows.append(
            f"<tr><td class='num'>{escape(p['id'])}</td><td>{escape(', '.join(p['elements']))}</td>"
            f"<td>{' / '.join(_mode_badge(m) for m in p['modes'])}</td><td class='num'>{decimal(p['distance'], 3, missing=MISSING)}</td>"
            f"<td class='num'>{percent(probs[0], missing=MISSING)} / {percent(probs[1], missing=MISSING)}</td>"
            f"<td class='num'>{percent(var[0], missing=MISSING)} / {percent(var[1], missing=MISSING)}</td>"
            f"<td class='num'>{percent(p.get('p_straddle'), missing=MISSING)}</td><td>{escape(verdict)}{reason}</td></tr>"
        )
    note = (
        f"<p class=\"muted\">P: share of dithers that show the side's predicted outcome (mode and the pair's "
        f"elements) under the expected execution noise ({noise}); a side needs {percent(dith.get('target'), missing=MISSING)}. "
        "P straddle: the chance that both flown sides (each its variant where one is flown) show their outcomes, "
        "each its own run: the product of their P. The plan keeps the pairs most likely to show.</p>"
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
        seen = ", ".join(f"{escape(k)} {escape(v)}" for k, v in (d.get("modes") or {}).items()) or MISSING
        subs = d.get("sub_boundaries") or []
        if subs:
            sub_html = "<br>".join(
                f"{escape(b.get('element', '?'))} <em>({escape(b.get('relation', '?'))})</em>: "
                f"{percent(b.get('share'), missing=MISSING)} of runs, nearest {decimal(b.get('nearest'), missing=MISSING)}"
                for b in subs
            )
        elif d:
            sub_html = "none found"
        else:
            sub_html = MISSING
        runs = f"{escape(d.get('valid', MISSING))} / {escape(d.get('runs', MISSING))}" if d else "not dithered"
        p = d.get("p_predicted_mode")
        warn = ' <span class="note">(fragile)</span>' if p is not None and float(p) < 0.6 else ""
        rows.append(
            f"<tr><td>{escape(s['id'])}</td><td>{_mode_badge(mode)} {escape(MODE_LABELS.get(mode, ''))}</td>"
            f"<td class='num'>{percent(p, missing=MISSING)}{warn}</td><td class='num'>{runs}</td><td>{seen}</td>"
            f"<td class='num'>{decimal(d.get('nearest_other_mode'), missing=MISSING)}</td><td>{sub_html}</td></tr>"
        )
    return f"<table>{head}{''.join(rows)}</table>"


def _parameter_table(scen: list[dict]) -> str:
    names: list[str] = []
    for s in scen:
        for n in s.get("parameters") or {}:
            if n not in names:
                names.append(n)
    head = "<tr><th>parameter</th>" + "".join(f"<th>{escape(s['id'])}</th>" for s in scen) + "</tr>"

    def cell(v):
        if isinstance(v, (list, tuple)):
            return escape(" → ".join(str(x) for x in v))
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return decimal(v, 4, missing=MISSING)
        return escape(v)

    rows = "".join(
        f"<tr><td>{escape(n)}</td>"
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
                links.append(f'<a href="{escape(quote(name))}">{escape(name)}</a>')
            else:
                links.append(f'<span class="muted">{escape(name)} (missing)</span>')
        mode = (s.get("predicted") or {}).get("mode", "?")
        p = (s.get("dithering") or {}).get("p_predicted_mode")
        rows.append(
            f"<tr><td class='num'>{n}</td><td>{escape(sid)}</td><td>{escape(pair_of.get(sid, MISSING))}</td>"
            f"<td>{_mode_badge(mode)}</td><td class='num'>{percent(p, missing=MISSING)}</td><td>{' · '.join(links) or MISSING}</td></tr>"
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
    body.append(
        f'<section class="pair" id="pair-{escape(pid)}"><h3>Pair {escape(pair.get("id"))}: {escape(elements)}</h3>'
    )
    body.append(
        f"<p>Score-tree level {escape(pair.get('level', '?'))}; modes "
        + " / ".join(_mode_badge(m) for m in modes)
        + f"; distance in the unit cube {decimal(pair.get('distance'), missing=MISSING)}; scenarios "
        + ", ".join(escape(s["id"]) for s in scen)
        + ".</p>"
    )
    if not scen:
        body.append('<p class="note">The pair\'s scenarios are missing from the plan.</p></section>')
        return body
    note = pair_map_figure(pair, scen, out_dir, fig_dir / f"pair{pid}_map.png")
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
        body.append(f'<p class="note">{escape(note)}</p>')
    parallel_figure(pair, scen, labels, owners, imp, fig_dir / f"pair{pid}_parallel.png")
    body.append(
        _img(
            f"{FIGURES_DIR}/pair{pid}_parallel.png",
            f"parallel coordinates of pair {pair.get('id')}",
            "Unit-cube coordinates of both scenarios (a permutation spans several shaded "
            "coordinates, one key per item); below, each coordinate's importance for mission "
            "and safety success.",
        )
    )
    if dim >= 2 and dithers_figure(pair, scen, dithers, labels, axes_idx, fig_dir / f"pair{pid}_dithers.png"):
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

    ``plan`` is a field plan (as :func:`planner.plan.generate.generate` returns it or
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
    modes_figure(plan, fig_dir / "modes.png")
    top = boundary_types_figure(plan, fig_dir / "boundary_types.png")
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
    roots = sensitivity_figure(plan, fig_dir / "sensitivity.png")
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
        f"(schema {escape(PLAN_SCHEMA)}).</p></main>"
    )
    title = f"RAPT field plan: {plan['mission'].get('name', '?')}"
    page = (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width, initial-scale=1"><title>{escape(title)}</title>'
        f"<style>{_CSS}</style></head><body>\n" + "\n".join(body) + "\n</body></html>\n"
    )
    path = out_dir / REPORT_NAME
    write_text_atomic(path, page)
    return path
