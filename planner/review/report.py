"""``comparison.html``: predicted against observed runs, the bias estimate and the re-plan table.

One self-contained page beside ``comparison.json`` (inline CSS, PNG figures in
``figures/``, no JavaScript, nothing from the network), drawn headless with matplotlib's
Agg backend like the plan's own report:

* what was lost from damaged or truncated logs;
* the execution bias estimate: each parameter with its standard error and neutral value;
* mode agreement before and after the bias correction;
* per logged run a map: the mission's elements for that scenario, the predicted track
  (as planned), the track re-predicted under the fitted bias, and the observed track;
* how sure the predictions were: per run the mode probabilities under the plan's execution
  noise alone and with the fitted bias's uncertainty, and the day's Brier scores;
* per pair: did it straddle its boundary on the water, does it still under the bias, and
  with what probability under the corrected forecast;
* the re-plan table: the adjusted "M" scenarios proposed for the next runs.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import numpy as np

from planner.common.atomic import write_text_atomic
from planner.common.html.figures import draw_area, label_map_axes, rectangle_corners, save_figure
from planner.common.html.text import EN_DASH, escape, percent, significant
from planner.review.confirmations import side_summary
from sim.uuv.scenario import make_scenarios

__all__ = ["write_comparison_report", "REPORT_NAME"]

REPORT_NAME = "comparison.html"
FIGURES = "figures"
CSS = """body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#eee}td.l,th.l{text-align:left}.bad{color:#b00020;font-weight:bold}.ok{color:#1b7f2a}
img{max-width:100%}.warn{background:#fff4e5;border-left:4px solid #f0a020;padding:.5em 1em}"""


#: A missing value (the plan's report writes an em dash).
MISSING = EN_DASH


def _e(v: Any) -> str:
    """Text escaped; a missing one (None) written as nothing."""
    return escape(v, none="")


def _num(v: Any, digits: int = 3) -> str:
    return significant(v, digits, missing=MISSING)


def _differ(row: dict) -> str:
    """Sub-scores (level 1) whose observed value is not the predicted one, as name predicted→observed."""
    out = []
    for name, v in row.get("sub_scores", {}).items():
        if v["observed"] is not None and v["observed"] != v["predicted"]:
            out.append(f"{name} {v['predicted']:g}→{v['observed']:g}")
    return ", ".join(out) or MISSING


def _rects(ax, rects: np.ndarray, face: str, edge: str, alpha: float, label: str | None = None) -> None:
    for i, (x0, x1, y0, y1) in enumerate(np.asarray(rects).reshape(-1, 4)):
        draw_area(
            ax, rectangle_corners(x0, x1, y0, y1), face=face, edge=edge, alpha=alpha, label=label if i == 0 else None
        )


def _map(plan, sid: str, track: np.ndarray, predicted, corrected, row: dict, path: Path, calibrated=None) -> None:
    m = plan.mission
    scen = make_scenarios(m, plan.u(sid)[None, :])
    fig, ax = plt.subplots(figsize=(5.2, 6.0))
    op = m.operational_area
    x0, y0 = op.x - op.width / 2, op.y - op.height / 2
    draw_area(ax, rectangle_corners(x0, x0 + op.width, y0, y0 + op.height), face=None, edge="#333")
    _rects(ax, scen.area_rect[0], "#4daf4a", "#2b7a28", 0.3, "mission area")
    if m.transmission is not None:
        _rects(ax, scen.tx_rect[0], "#80b1d3", "#377eb8", 0.3, "transmission")
    _rects(ax, scen.nogo[0], "#e41a1c", "#a50f15", 0.35, "no-go")
    _rects(ax, scen.barriers[0], "#984ea3", "#54278f", 0.35, "barrier")
    if m.waypoints:
        w = np.array(m.waypoints)
        ax.plot(w[:, 0], w[:, 1], "k^", ms=6, label="waypoint")
    ax.plot(*m.recovery, "ks", ms=6, label="recovery")
    if predicted is not None:
        ax.plot(
            predicted[:, 1], predicted[:, 2], "--", color="#555", lw=1.2, label=f"predicted ({row['predicted_mode']})"
        )
    if track.shape[0]:
        ax.plot(
            track[:, 1],
            track[:, 2],
            "-",
            color="#d62728",
            lw=2.4,
            alpha=0.55,
            label=f"observed ({row['observed_mode'] or 'end not logged'})",
        )
    if calibrated is not None:
        ax.plot(
            calibrated[:, 1],
            calibrated[:, 2],
            "-.",
            color="#2ca02c",
            lw=1.3,
            label=f"calibrated vehicle ({row.get('calibrated_mode')})",
        )
    if corrected is not None:  # on top: where it overlays the observed track, the bias explains the run
        ax.plot(
            corrected[:, 1],
            corrected[:, 2],
            ":",
            color="#1f4e9c",
            lw=1.4,
            label=f"bias-corrected ({row['corrected_mode']})",
        )
    ax.set_aspect("equal")
    ax.set_xlim(op.x - op.width / 2 - 20, op.x + op.width / 2 + 20)
    ax.set_ylim(op.y - op.height / 2 - 20, op.y + op.height / 2 + 20)
    label_map_axes(ax)
    err = row.get("path_error_m")
    ax.set_title(f"{sid}: path error {err:.1f} m" if err is not None else sid, fontsize=10)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=3, frameon=False)
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def _bias_figure(result: dict, path: Path) -> None:
    bias, neutral, units = result["bias"], result["bias_fit"]["neutral"], result["bias_fit"]["units"]
    names = list(bias)
    fig, axes = plt.subplots(1, len(names), figsize=(1.7 * len(names), 2.6))
    for ax, n in zip(np.atleast_1d(axes), names):
        est, se = bias[n]["estimate"], bias[n]["stderr"]
        prior = bias[n].get("prior")
        ax.axhline(neutral[n], color="#999", lw=1)
        if prior:  # the prior's +- 2 s.d. band: an estimate as wide as this was not identified
            ax.axhspan(prior["centre"] - 2 * prior["sd"], prior["centre"] + 2 * prior["sd"], color="#eee")
        colour = "#1f77b4" if bias[n].get("identified") else "#999"
        ax.errorbar([0], [est], yerr=[[2 * se if se else 0]], fmt="o", color=colour, capsize=4)
        ax.set_xticks([])
        ax.set_title(f"{n}\n({units[n]})", fontsize=8)
        ax.tick_params(labelsize=7)
    fig.suptitle(
        "execution bias: estimate ± 2 s.e. (line: neutral, band: prior ± 2 s.d., grey: not identified)", fontsize=9
    )
    fig.tight_layout()
    save_figure(fig, path, dpi=90)


def _bias_section(result: dict, fig_dir: Path) -> list[str]:
    """The fitted execution bias, its figure and how often the modes agreed."""
    parts: list[str] = []
    _bias_figure(result, fig_dir / "bias.png")
    fitd = result["bias_fit"]
    parts.append(
        "<h2>Execution bias</h2><table><tr><th class='l'>parameter</th><th>estimate</th><th>std. error</th>"
        "<th>prior</th><th class='l'>identified</th><th class='l'>unit</th></tr>"
    )
    for n, v in result["bias"].items():
        prior = v.get("prior")
        prior_text = "not fitted" if prior is None else f"{prior['centre']:g} ± {prior['sd']:g}"
        ident = "yes" if v["identified"] else "no: kept neutral"
        parts.append(
            f"<tr><td class='l'>{_e(n)}</td><td>{v['estimate']:.4g}</td><td>{v['stderr']:.2g}</td>"
            f"<td>{_e(prior_text)}</td><td class='l'>{ident}</td><td class='l'>{_e(fitd['units'][n])}</td></tr>"
        )
    parts.append(
        f"</table><p>Fitted on {fitd['runs']} run(s), {fitd['segments']} open-loop segments: position "
        f"residual {fitd['rms_position_m']:.3g} m RMS (unbiased model: {fitd['rms_position_unbiased_m']:.3g} m), "
        f"energy residual {fitd['rms_energy_wh']:.3g} Wh RMS.</p><img src='{FIGURES}/bias.png' alt='bias'>"
    )
    ag = result["mode_agreement"]

    def pct(v: float | None) -> str:
        return percent(v, missing=MISSING)

    cv = result["cross_validation"]
    held, path = cv["held_out_mode_agreement"], cv["held_out_path_error_m"]

    def metres(v: float | None) -> str:
        return MISSING if v is None else f"{v:.1f} m"

    parts.append(
        "<h2>Is the correction worth using?</h2><p>Leave one log out: fit on the others, predict the "
        f"left-out run. Held-out mode agreement <b>{pct(held['uncorrected'])}</b> uncorrected, "
        f"<b>{pct(held['corrected'])}</b> corrected ({held['runs']} runs); held-out path error "
        f"{metres(path['uncorrected'])} uncorrected, {metres(path['corrected'])} corrected.</p>"
        f"<p><b>{_e(result['correction']['note'])}</b></p>"
    )
    parts.append(
        f"<h2>Mode agreement</h2><p>Predicted modes matched the observed ones on <b>{pct(ag['uncorrected'])}"
        f"</b> of {ag['scenarios']} scenario(s) as planned, and on <b>{pct(ag['corrected'])}</b> with the "
        "correction used (the same as planned when it is not used).</p>"
    )
    return parts


def _scenario_section(result: dict, plan, tracks: list[tuple[str, np.ndarray]], traj: dict, fig_dir: Path) -> list[str]:
    """Per scenario: predicted, observed and corrected modes, path errors, and its map."""
    parts: list[str] = []
    parts.append(
        "<h2>Scenarios</h2><table><tr><th class='l'>scenario</th><th class='l'>log</th><th>predicted</th>"
        "<th>observed</th><th>corrected</th><th>path error (m)</th><th>corrected (m)</th>"
        "<th class='l'>ended</th><th class='l'>sub-scores not as predicted</th></tr>"
    )
    for r in result["scenarios"]:
        cls = "ok" if r["observed_mode"] == r["predicted_mode"] else "bad"
        parts.append(
            f"<tr><td class='l'>{_e(r['id'])}</td><td class='l'>{_e(r['log'])}</td>"
            f"<td>{_e(r['predicted_mode'])}</td><td class='{cls}'>{_e(r['observed_mode'] or MISSING)}</td>"
            f"<td>{_e(r['corrected_mode'])}</td><td>{_num(r['path_error_m'])}</td>"
            f"<td>{_num(r['path_error_corrected_m'])}</td><td class='l'>{_e(r['ended'] or 'not in log')}</td>"
            f"<td class='l'>{_e(_differ(r))}</td></tr>"
        )
    parts.append("</table>")
    calibrated = any("calibrated_mode" in r for r in result["scenarios"])
    if calibrated:
        parts.append(
            "<p>Calibrated: predicted with the calibrated vehicle model (rapt-plan calibrate), before any bias.</p>"
            "<table><tr><th class='l'>scenario</th><th>predicted</th><th>calibrated</th><th>observed</th>"
            "<th>path error as planned (m)</th><th>calibrated (m)</th></tr>"
        )
        for r in result["scenarios"]:
            parts.append(
                f"<tr><td class='l'>{_e(r['id'])}</td><td>{_e(r['predicted_mode'])}</td>"
                f"<td>{_e(r['calibrated_mode'])}</td><td>{_e(r['observed_mode'] or MISSING)}</td>"
                f"<td>{_num(r['path_error_m'])}</td><td>{_num(r['path_error_calibrated_m'])}</td></tr>"
            )
        parts.append("</table>")
    for i, (sid, track) in enumerate(tracks):
        row = result["scenarios"][i]
        name = f"run{i + 1}_{sid}.png".replace("/", "_")
        p, c, k = traj.get(sid, (None, None, None))
        _map(plan, sid, track, p, c, row, fig_dir / name, k)
        parts.append(f"<img src='{FIGURES}/{_e(name)}' alt='{_e(sid)}' style='width:48%'>")
    return parts


def _checks_section(result: dict) -> list[str]:
    """Per log, its automatic run checks (planner.review.run_checks): verdict, evidence, why; and which runs the
    bias fit left out."""
    names = [c["name"] for c in (result["logs"][0].get("checks") or [])] if result["logs"] else []
    if not names:
        return []
    head = "".join(f"<th>{_e(n)}</th>" for n in names)
    parts = [f"<h2>Run checks</h2><table><tr><th class='l'>log</th>{head}</tr>"]
    cls = {"pass": "ok", "fail": "bad", "warn": "", "unknown": ""}
    details = []
    for lg in result["logs"]:
        log = Path(lg["path"]).name
        cells = ""
        for c in lg.get("checks") or []:
            title = f"{c['reason']} (at {c['time_s']} s)" if c.get("time_s") is not None else c["reason"]
            cells += f"<td class='{cls[c['verdict']]}' title='{_e(title)}'>{_e(c['verdict'])}</td>"
            if c["verdict"] != "pass":
                at = "" if c.get("time_s") is None else f" at {c['time_s']:.1f} s"
                details.append(
                    f"<li><code>{_e(log)}</code> {_e(c['name'])} <b>{_e(c['verdict'])}</b>{at}: {_e(c['reason'])}</li>"
                )
        parts.append(f"<tr><td class='l'>{_e(log)}</td>{cells}</tr>")
    parts.append("</table>")
    if details:
        parts.append("<ul>" + "".join(details) + "</ul>")
    excluded = result.get("run_checks", {}).get("excluded_from_bias_fit") or []
    if excluded:
        parts.append(
            "<p class='warn'>Not counted in the bias fit (a check failed; <code>--keep-failed</code> counts them): "
            + ", ".join(f"<code>{_e(n)}</code>" for n in excluded)
            + "</p>"
        )
    return parts


def _forecast_section(result: dict) -> list[str]:
    """Per run the forecasts' mode probabilities beside the deterministic prediction, and the day's Brier scores."""
    fc = result["forecast"]
    b = fc["brier"]
    used = "bias + noise" if fc["corrected_is"] == "bias_noise" else "noise only"
    parts = [
        "<h2>How sure were the predictions?</h2><p>Each scenario forecast from "
        f"{fc['draws']} seeded runs (seed {fc['seed']}) under the execution noise fitted to the day's runs alone, and with each run "
        f"also under a draw of the fitted bias (varied: {_e(', '.join(fc['bias_varied']) or 'none identified')}). "
        f"The corrected forecast is <b>{used}</b>.</p>",
        "<table><tr><th class='l'>scenario</th><th class='l'>log</th><th>observed</th><th>deterministic</th>"
        "<th class='l'>noise only</th><th class='l'>bias + noise</th><th>P(observed) noise</th>"
        "<th>P(observed) bias + noise</th></tr>",
    ]

    def dist(d: dict | None) -> str:
        return MISSING if d is None else ", ".join(f"{m} {p:.2f}" for m, p in d.items() if p > 0)

    for r in result["scenarios"]:
        f = r["forecast"]
        parts.append(
            f"<tr><td class='l'>{_e(r['id'])}</td><td class='l'>{_e(r['log'])}</td>"
            f"<td>{_e(r['observed_mode'] or MISSING)}</td><td>{_e(f['deterministic']['corrected'])}</td>"
            f"<td class='l'>{_e(dist(f['modes']['noise']))}</td><td class='l'>{_e(dist(f['modes']['bias_noise']))}</td>"
            f"<td>{_num(f['p_observed_mode']['noise'])}</td><td>{_num(f['p_observed_mode']['bias_noise'])}</td></tr>"
        )
    parts.append(
        f"</table><p>The day's Brier score over {b['runs']} run(s) with a logged end (0 is perfect; modes: "
        "multi-class, at most 2; held: whether the plan's predicted mode held, at most 1):</p>"
        "<table><tr><th class='l'>prediction</th><th>modes</th><th>held</th></tr>"
    )
    for key, label in (
        ("deterministic_uncorrected", "deterministic, as planned"),
        ("deterministic_corrected", "deterministic, corrected"),
        ("noise", "execution noise only"),
        ("bias_noise", "fitted bias's uncertainty + execution noise"),
        ("corrected_assumed_noise", "corrected, under the plan's assumed noise"),
    ):
        if key in b:
            parts.append(
                f"<tr><td class='l'>{label}</td><td>{_num(b[key]['mode'])}</td><td>{_num(b[key]['held'])}</td></tr>"
            )
    parts.append("</table>")
    noise = fc.get("day_noise") or {}
    if noise.get("note"):
        parts.append(f"<p>The day's execution noise (the plan's assumption as the prior): {_e(noise['note'])}.</p>")
    parts.append(
        "<p>Reliability of the corrected forecast: runs binned by their forecast P(the predicted mode held), "
        "against the share that held.</p><table><tr><th>P held</th><th>runs</th><th>mean P</th><th>held</th></tr>"
    )
    for row in fc.get("reliability", []):
        parts.append(
            f"<tr><td>{row['p_low']:.1f}–{row['p_high']:.1f}</td><td>{row['runs']}</td>"
            f"<td>{_num(row['mean_p'])}</td><td>{_num(row['held'])}</td></tr>"
        )
    parts.append("</table>")
    return parts


def _pair_section(result: dict) -> list[str]:
    """Per pair: whether it straddled its boundary on the water and still does under the bias."""
    parts: list[str] = []
    parts.append(
        "<h2>Pairs</h2><table><tr><th>pair</th><th class='l'>scenarios</th><th class='l'>elements</th>"
        "<th>predicted</th><th>observed</th><th>straddled on the water</th><th>P(straddles)</th>"
        "<th>deterministic, under the bias</th><th>verdict</th></tr>"
    )

    def yn(v: bool | None) -> str:
        return MISSING if v is None else ("yes" if v else "<span class='bad'>no</span>")

    for p in result["pairs"]:
        parts.append(
            f"<tr><td>{_e(p['id'])}</td><td class='l'>{_e(' / '.join(p['scenarios']))}</td>"
            f"<td class='l'>{_e(', '.join(p['elements']))}</td><td>{_e(' / '.join(p['predicted_modes']))}</td>"
            f"<td>{_e(' / '.join(m or MISSING for m in p['observed_modes']))}</td>"
            f"<td>{yn(p['observed_straddles'])}</td><td>{_num(p.get('p_straddles'), 2)}</td>"
            f"<td>{'moved: ' + _e(', '.join(p['moved_sides'])) if p['flagged_deterministic'] else 'holds'}</td>"
            f"<td>{'<span class=bad>flagged: ' + _e(p.get('reason')) + '</span>' if p['flagged'] else 'holds'}"
            "</td></tr>"
        )
    parts.append("</table>")
    return parts


def _confirmation_section(result: dict) -> list[str]:
    """Per pair: each side's runs that showed its outcome, by scenario flown, and whether the boundary is confirmed."""
    parts = [
        "<h2>Boundaries confirmed</h2><p>A side has shown its boundary when its runs say so at 3:1 odds "
        "(P(q &gt; 1/2) &ge; 0.75 under a uniform prior: one run that shows; 3 of 4 after a miss); a pair is "
        "confirmed when both sides have.</p><table><tr><th>pair</th><th class='l'>side a</th>"
        "<th class='l'>side b</th><th>status</th></tr>"
    ]

    for p in result.get("confirmation", []):
        status = p["status"] if p["status"] == "confirmed" else f"<span class='bad'>{_e(p['status'])}</span>"
        parts.append(
            f"<tr><td>{_e(p['id'])}</td><td class='l'>{_e(side_summary(p['sides'][0]))}</td>"
            f"<td class='l'>{_e(side_summary(p['sides'][1]))}</td><td>{status}</td></tr>"
        )
    parts.append("</table>")
    return parts


def _replan_section(result: dict) -> list[str]:
    """The adjusted scenarios proposed for the next runs, and the unflown ones re-predicted."""
    parts = ["<h2>Re-plan: adjusted scenarios for the next runs</h2>"]
    if not result["proposals"]:
        parts.append("<p>Every pair still straddles its boundary under the fitted bias; no adjustment needed.</p>")
    else:
        parts.append(
            "<table><tr><th class='l'>new</th><th class='l'>replaces</th><th class='l'>move</th>"
            "<th>mode under bias</th><th>P(intended) in dithers</th></tr>"
        )
        for q in result["proposals"]:
            if q["found"]:
                mv = q["moved"]
                move = f"{mv['parameter']}: {_num(mv['from'], 5)} → {_num(mv['to'], 5)}"
                parts.append(
                    f"<tr><td class='l'>{_e(q['id'])}</td><td class='l'>{_e(q['variant_of'])}</td>"
                    f"<td class='l'>{_e(move)}</td><td>{_e(q['predicted_mode_under_bias'])}</td>"
                    f"<td>{_num(q['p_intended'])}{'' if q['robust'] else ' (fragile)'}</td></tr>"
                )
            else:
                parts.append(
                    f"<tr><td class='l'>{MISSING}</td><td class='l'>{_e(q['variant_of'])}</td>"
                    f"<td class='l' colspan=3>{_e(q['note'])}</td></tr>"
                )
        parts.append("</table>")
    if result["remaining"]:
        parts.append(
            "<h3>Scenarios not flown yet, re-predicted</h3><table><tr><th class='l'>scenario</th>"
            "<th>as planned</th><th>under the bias</th></tr>"
        )
        for r in result["remaining"]:
            parts.append(
                f"<tr><td class='l'>{_e(r['id'])}</td><td>{_e(r['predicted_mode'])}</td>"
                f"<td class='{'bad' if r['changed'] else 'ok'}'>{_e(r['corrected_mode'])}</td></tr>"
            )
        parts.append("</table>")
    return parts


def write_comparison_report(
    result: dict, plan, tracks: list[tuple[str, np.ndarray]], traj: dict, out_dir: Path
) -> Path:
    """Write ``comparison.html`` and its figures into ``out_dir``; returns the page's path."""
    out_dir = Path(out_dir)
    fig_dir = out_dir / FIGURES
    fig_dir.mkdir(parents=True, exist_ok=True)
    parts = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>RAPT comparison: {_e(result['plan']['mission'])}"
        f"</title><style>{CSS}</style></head><body>",
        f"<h1>Range day against plan {_e(result['plan']['id'])} ({_e(result['plan']['mission'])})</h1>",
        f"<p>{len(result['logs'])} log(s) of plan <code>{_e(result['plan']['path'])}</code>.</p>",
    ]
    lost = [(lg["path"], p) for lg in result["logs"] for p in lg["lost"]]
    if lost:
        parts.append(
            "<div class='warn'><b>What the logs lost</b><ul>"
            + "".join(f"<li><code>{_e(Path(p).name)}</code>: {_e(msg)}</li>" for p, msg in lost)
            + "</ul></div>"
        )
    parts += _checks_section(result)
    parts += _bias_section(result, fig_dir)
    parts += _scenario_section(result, plan, tracks, traj, fig_dir)
    parts += _forecast_section(result)
    parts += _pair_section(result)
    parts += _confirmation_section(result)
    parts += _replan_section(result)
    parts.append("</body></html>")
    page = out_dir / REPORT_NAME
    write_text_atomic(page, "\n".join(parts))
    return page
