"""``rapt-plan next``: the afternoon conducted run by run.

A range day is a fixed budget of runs.  After each run, :func:`conduct` reads the plan and
the day's logs so far (any of its scenarios, repeats allowed; a log already read is not read
again, :mod:`planner.conduct.day_record`), updates the day's fit (the afternoon's bias, folded
in log by log; the noise's scale, weighed by the outcomes the runs showed,
:mod:`planner.conduct.side_forecast`), and names the one run that most raises the expected
number of boundaries confirmed by the end of the day with the runs left
(:func:`rapt.confirmation.next_run`):

* a side not flown yet (the scenario itself or its robust variant, whichever is likelier to show);
* a side that came out against its prediction, flown again, or moved: a new variant found
  in the day's water (:mod:`planner.conduct.side_moves`), written into the plan with its range files;
* or stop, when no run raises the expected confirmations.

A boundary is confirmed by :mod:`planner.review.confirmations`' rule, the one ``rapt-plan compare``
reports.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from planner.common.plans import Plan, load_plan
from planner.conduct.day_record import DayRecord, load_record, read_logs, update_bias
from planner.conduct.side_forecast import SideForecasts, Target, forecast_sides
from planner.conduct.side_moves import Move, add_variant, find_move, variant_id
from planner.plan.dithering import Outcome
from planner.review.confirmations import RunOutcome, confirmation_table, outcome_columns, side_scenarios
from planner.review.forecast import plan_noise
from planner.review.runs import predict_plan
from rapt.confirmation import Option, Pair, Side, next_run
from rapt.errors import InputError
from sim.uuv.bias import compose
from sim.uuv.scoring import mode_name

__all__ = ["conduct", "MOVE_BELOW"]

#: A side that missed is moved when none of its scenarios' next runs shows with at least this chance.
MOVE_BELOW = 0.8
SIDE_NAMES = ("a", "b")


@dataclass
class _Day:
    """Everything one call knows: the plan, its predictions, the runs, the forecasts and the candidate moves."""

    plan: Plan
    record: DayRecord
    keys: list[str]
    names: list[str]
    predicted: dict[str, np.ndarray]
    runs: list[RunOutcome]
    forecasts: SideForecasts | None = None
    moves: dict[str, Move] | None = None


def check_writable(plan_path: Path) -> Path:
    """The plan file; InputError (one line) when its directory or file cannot be written, before anything else."""
    plan_file = plan_path / "plan.json" if plan_path.is_dir() else plan_path
    directory = plan_file.parent
    if plan_file.is_file() and not (os.access(directory, os.W_OK) and os.access(plan_file, os.W_OK)):
        raise InputError(
            f"PLAN: {directory} cannot be written; next adds the day's moved scenarios and its record there: "
            "copy the plan directory somewhere writable"
        )
    return plan_file


def conduct(
    plan_path: str | Path,
    log_paths: Sequence[str | Path],
    runs_left: int,
    seed: int = 0,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """The next run of the afternoon (module docstring): what ``--json`` prints, with the confirmation table."""
    t0 = time.perf_counter()
    say = progress or (lambda _: None)
    plan_file = check_writable(Path(plan_path))
    if runs_left < 0:
        raise InputError(f"--runs-left: expected the runs left today (>= 0), got {runs_left}")
    plan = load_plan(plan_file)
    paths = [Path(p) for p in log_paths]
    for p in paths:
        if not p.is_file():
            raise InputError(f"LOG: {p} does not exist; give the .mcap logs of today's runs of this plan")
    record = load_record(plan_file.parent, plan)
    say("reading new logs")
    keys, fresh = read_logs(plan, paths, record)
    ids, _, pred = predict_plan(plan)
    row = {sid: k for k, sid in enumerate(ids)}
    runs = [
        RunOutcome(r.scenario, None if r.scores is None else np.asarray(r.scores), Path(r.path).name)
        for r in (record.logs[k] for k in keys)
        if r.checks_passed
    ]
    day = _Day(plan, record, keys, list(pred.names), {s: pred.scores[row[s]] for s in ids}, runs)
    table = confirmation_table(plan, day.names, day.predicted, runs)
    if runs_left == 0:
        record.save(plan_file.parent)
        confirmed = sum(p["status"] == "confirmed" for p in table)
        reason = f"done: no runs left; {confirmed} of {len(table)} boundaries confirmed"
        return _result(day, None, reason, table, [1.0 if p["status"] == "confirmed" else 0.0 for p in table], t0)
    say("updating the day's bias")
    update_bias(plan, record, keys, fresh)
    say("forecasting the sides in the day's water")
    targets = _targets(day)
    day.forecasts = forecast_sides(plan.mission, targets, _flown(day, targets), plan_noise(plan), _bias(record), seed)
    say("moving sides that came out against their prediction")
    day.moves = _moves(day, targets, seed)
    pairs, options = _pairs(day)
    choice = next_run(pairs, runs_left)
    p_confirm = [1.0 if p.confirmed else q for p, q in zip(pairs, choice.p_confirm)]
    status = ["confirmed" if p.confirmed else "lost" if lost else "open" for p, lost in zip(pairs, choice.lost)]
    if choice.pair is None:
        done = sum(p.confirmed for p in pairs)
        reason = f"stop: no run raises the boundaries expected confirmed ({done} of {len(pairs)} confirmed)"
        record.save(plan_file.parent)
        return _result(day, None, reason, table, p_confirm, t0, status)
    assert choice.side is not None and choice.option is not None
    sid, reason = _chosen(day, choice.pair, choice.side, options[choice.pair][choice.side][choice.option], keys)
    record.save(plan_file.parent)
    return _result(day, sid, reason, table, p_confirm, t0, status)


def _bias(record: DayRecord) -> tuple[dict[str, float], dict[str, float], list[str]]:
    varied = [n for n in record.centre if record.identified(n)]
    return record.bias().to_dict(), record.sd, varied


def _side_target(day: _Day, pair: dict, sid: str) -> tuple[tuple[int, ...], tuple[float, ...]]:
    cols = outcome_columns(pair, day.names)
    return tuple(cols), tuple(float(v) for v in day.predicted[sid][cols])


def _targets(day: _Day) -> dict[str, Target]:
    """Every scenario flown for a pair side, with the side's outcome."""
    out = {}
    for pair in day.plan.pairs:
        for sid in pair["scenarios"]:
            cols, values = _side_target(day, pair, sid)
            for scen in side_scenarios(day.plan, sid):
                out[scen] = Target(day.plan.u(scen), cols, values)
    return out


def _showed(run: RunOutcome, t: Target) -> bool:
    return run.scores is not None and bool(np.array_equal(run.scores[list(t.columns)], np.asarray(t.values)))


def _flown(day: _Day, targets: dict[str, Target]) -> list[tuple[str, bool]]:
    return [(r.sid, _showed(r, targets[r.sid])) for r in day.runs if r.sid in targets and r.scores is not None]


def _record(day: _Day, scen: str, t: Target) -> tuple[int, int]:
    ended = [r for r in day.runs if r.sid == scen and r.scores is not None]
    shown = sum(_showed(r, t) for r in ended)
    return shown, len(ended) - shown


def _moves(day: _Day, targets: dict[str, Target], seed: int) -> dict[str, Move]:
    """A candidate move for each side that missed and has no scenario likely to show on its next run."""
    assert day.forecasts is not None
    plan, fc = day.plan, day.forecasts
    mission = replace(plan.mission, execution_bias=compose(plan.mission.execution_bias, day.record.bias()))
    sigma = plan_noise(plan) * fc.scale
    out = {}
    for pair in plan.pairs:
        for j, sid in enumerate(pair["scenarios"]):
            scen = side_scenarios(plan, sid)
            recs = {s: _record(day, s, targets[s]) for s in scen}
            if not any(f for _, f in recs.values()) or any(k > f for k, f in recs.values()):
                continue  # no miss, or a scenario already ahead
            best = max(Option(fc.p[s], *recs[s]).p_next for s in scen)
            if best >= MOVE_BELOW:
                continue
            last = next(r.sid for r in reversed(day.runs) if r.sid in scen)
            t = targets[last]
            outcome = Outcome(int(2 * t.values[0] + t.values[1]), t.columns, t.values)
            partner = plan.u(pair["scenarios"][1 - j])
            move = find_move(
                mission,
                plan.mission,
                sid,
                (last, plan.u(last)),
                partner,
                outcome,
                fc.dithers[last],
                plan.sensitivity(),
                sigma,
                seed,
            )
            if move is not None:
                out[sid] = move
    return out


def _pairs(day: _Day) -> tuple[list[Pair], list[list[list[str | Move]]]]:
    """The pairs as :mod:`rapt.confirmation` plans them, and per pair and side the options (scenario ids or a move)."""
    assert day.forecasts is not None and day.moves is not None
    targets = _targets(day)
    pairs, options = [], []
    for pair in day.plan.pairs:
        sides, opts = [], []
        for sid in pair["scenarios"]:
            ids = side_scenarios(day.plan, sid)
            side = [Option(day.forecasts.p[s], *_record(day, s, targets[s])) for s in ids]
            scen: list[str | Move] = list(ids)
            if sid in day.moves:
                scen.append(day.moves[sid])
                side.append(Option(day.moves[sid].p))
            sides.append(Side(tuple(side)))
            opts.append(scen)
        pairs.append(Pair((sides[0], sides[1])))
        options.append(opts)
    return pairs, options


def _chosen(day: _Day, i: int, j: int, option: str | Move, keys: list[str]) -> tuple[str, str]:
    """The scenario to fly (a move written into the plan first) and the one-line reason."""
    plan, fc = day.plan, day.forecasts
    assert fc is not None
    pair = plan.pairs[i]
    sid = pair["scenarios"][j]
    cols, values = _side_target(day, pair, sid)
    want = mode_name(_row(cols, values))
    who = f"pair {pair['id']}'s {SIDE_NAMES[j]} side"
    side_runs = [r for r in day.runs if r.sid in side_scenarios(plan, sid) and r.scores is not None]
    if isinstance(option, Move):
        last = side_runs[-1]
        logs = [Path(day.record.logs[k].path).name for k in keys]
        vid = variant_id(plan, sid)
        reason = (
            f"{who} came out {mode_name(_scores(last))}, predicted {want}; moved {option.sigmas:g}σ in "
            f"{option.parameter} as {vid} (P(shows {want}) {option.p:.2f})"
        )
        add_variant(plan, option, vid, reason, logs, day.record.bias().to_dict())
        return vid, reason
    scen = option
    t = Target(plan.u(scen), cols, values)
    shown, missed = _record(day, scen, t)
    p = Option(fc.p[scen], shown, missed).p_next
    if not side_runs:
        return scen, f"{who} not flown yet: fly {scen} (P(shows {want}) {p:.2f})"
    last = side_runs[-1]
    got = mode_name(_scores(last))
    if shown + missed == 0:
        return scen, f"{who} came out {got}, predicted {want}; fly its variant {scen} (P(shows {want}) {p:.2f})"
    return scen, (
        f"{who}: {shown} of {shown + missed} runs of {scen} showed {want} (last {got}); fly it again (P(shows) {p:.2f})"
    )


def _scores(run: RunOutcome) -> np.ndarray:
    assert run.scores is not None  # runs with an end only
    return run.scores


def _row(cols: tuple[int, ...], values: tuple[float, ...]) -> np.ndarray:
    out = np.zeros(max(cols) + 1)
    out[list(cols)] = values
    return out


def _result(
    day: _Day,
    sid: str | None,
    reason: str,
    table: list[dict],
    p_confirm: list[float],
    t0: float,
    status: list[str] | None = None,
) -> dict:
    status = status or [p["status"] for p in table]
    return {
        "next": None if sid is None else {"scenario": sid, "plan": str(day.plan.path)},
        "reason": reason,
        "pairs": [
            {"id": p["id"], "status": s, "p_confirm": round(float(q), 4)} for p, s, q in zip(table, status, p_confirm)
        ],
        "confirmation": table,
        "forecast": None
        if day.forecasts is None
        else {**day.forecasts.to_dict(), "p_shows": {k: round(v, 4) for k, v in day.forecasts.p.items()}},
        "bias": {
            "centre": day.record.bias().to_dict(),
            "identified": [n for n in day.record.sd if day.record.identified(n)],
        },
        "logs": len(day.keys),
        "seconds": round(time.perf_counter() - t0, 2),
    }
