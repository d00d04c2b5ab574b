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

import sim.uuv
from planner.common.plans import Plan, load_plan
from planner.conduct.day_record import DayRecord, load_record, read_logs, update_bias
from planner.conduct.new_pairs import NewPair, add_pair, candidate, new_pair_id, study_alternatives
from planner.conduct.side_forecast import SideForecasts, Target, forecast_sides
from planner.conduct.side_moves import Move, add_variant, find_move, variant_id
from planner.plan.dithering import Outcome
from planner.review.confirmations import (
    RunOutcome,
    boundaries_confirmed,
    confirmation_table,
    outcome_columns,
    shows,
    side_scenarios,
    target_scores,
)
from planner.review.forecast import plan_noise
from planner.review.runs import predict_plan
from rapt.confirmation import Option, Pair, Side, next_run
from rapt.errors import InputError
from sim.uuv.bias import NEUTRAL, compose
from sim.uuv.scoring import mode_name

__all__ = ["conduct", "afternoon", "decide", "Afternoon", "MOVE_BELOW"]

#: A side that missed is moved when none of its scenarios' next runs shows with at least this chance.
MOVE_BELOW = 0.8
SIDE_NAMES = ("a", "b")


@dataclass
class Afternoon:
    """Everything one call knows: the plan, its predictions, the runs, the forecasts and the candidate moves."""

    plan: Plan
    record: DayRecord
    names: list[str]
    predicted: dict[str, np.ndarray]
    runs: list[RunOutcome]
    forecasts: SideForecasts | None = None
    moves: dict[str, Move] | None = None
    bias_used: bool = False  # the forecasts and moves carry the afternoon's bias


def check_writable(plan_path: Path) -> Path:
    """The plan file; InputError (one line) when its directory or file cannot be written, before anything else.

    Tried, not inferred from permission bits: a read-only mount or an immutable file stops root as well.
    """
    plan_file = plan_path / "plan.json" if plan_path.is_dir() else plan_path
    directory = plan_file.parent
    if not plan_file.is_file():
        return plan_file  # load_plan says what is missing
    probe = directory / f".next-probe-{os.getpid()}"
    try:
        probe.touch()
        probe.unlink()
        with open(plan_file, "a"):
            pass
    except OSError as exc:
        raise InputError(
            f"PLAN: {directory} cannot be written ({exc.strerror}); next adds the day's moved scenarios and its "
            "record there: copy the plan directory somewhere writable"
        ) from None
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
    if runs_left > 0:
        say("updating the day's bias")
        update_bias(plan, record, keys, fresh)
    runs = [
        RunOutcome(r.scenario, None if r.scores is None else np.asarray(r.scores), Path(r.path).name)
        for r in (record.logs[k] for k in keys)
        if r.checks_passed
    ]
    if record.alternatives is None and runs_left > 0:
        say("reading the noon study's other pairs across each boundary")
        record.alternatives = study_alternatives(plan)
    say("forecasting the sides in the day's water")
    if record.forecast_seed != seed:
        record.forecasts, record.forecast_seed = {}, seed
    result = decide(afternoon(plan, runs, record), runs_left, seed, cache=record.forecasts)
    record.save(plan_file.parent)
    result["seconds"] = round(time.perf_counter() - t0, 2)
    return result


def afternoon(
    plan: Plan, runs: list[RunOutcome], record: DayRecord | None = None, known: Afternoon | None = None
) -> Afternoon:
    """The afternoon so far: ``runs`` (the day's runs of the plan, repeats included) and the bias ``record``
    (the plan's own day bias when None: an afternoon simulated without logs).  ``known``: an earlier afternoon
    of the same plan whose predictions are kept, only scenarios added since simulated (a simulated day)."""
    if known is None:
        ids, _, pred = predict_plan(plan)
        row = {sid: k for k, sid in enumerate(ids)}
        predicted = {s: pred.scores[row[s]] for s in ids}
        names = list(pred.names)
    else:
        predicted, names = dict(known.predicted), known.names
        new = [s["id"] for s in plan.scenarios + plan.variants if s["id"] not in predicted]
        if new:
            r = sim.uuv.simulate(plan.mission, np.array([plan.u(s) for s in new]))
            predicted.update({s: r.scores[k] for k, s in enumerate(new)})
    return Afternoon(plan, record or DayRecord(plan.id), names, predicted, list(runs))


def decide(
    day: Afternoon, runs_left: int, seed: int = 0, cache: dict | None = None, move_cache: dict | None = None
) -> dict:
    """The next run (or stop, or done at ``runs_left`` 0) and each pair's status: what ``--json`` prints, with the
    confirmation table, the forecasts and the bias.  ``cache`` (scenario -> forecast) spares the forecasts of
    scenarios already drawn under the same bias (:func:`planner.conduct.side_forecast.forecast_sides`);
    ``move_cache`` the moves already searched from the same scenario at the same noise (a simulated afternoon)."""
    plan = day.plan
    table = confirmation_table(plan, day.names, day.predicted, day.runs)
    if runs_left == 0:
        confirmed = boundaries_confirmed(plan, table)
        reason = f"done: no runs left; {confirmed} of {len(_originals(plan))} boundaries confirmed"
        status = {int(p["id"]): p["status"] for p in table}
        return _result(day, None, reason, table, {k: float(v == "confirmed") for k, v in status.items()}, status)
    targets = _targets(day)
    day.forecasts = _forecasts(day, targets, seed, cache)
    day.moves = _moves(day, targets, seed, {} if move_cache is None else move_cache)
    pairs, alts = _boundaries(day, targets, {})
    choice = next_run(pairs, runs_left)
    originals = _originals(plan)
    lost = [int(p["id"]) for p, gone in zip(originals, choice.lost) if gone and not _replacements(plan, p)]
    candidates = _candidates(day, lost)
    if candidates:  # a boundary fell through: new pairs across it, forecast with the others
        targets.update(_candidate_targets(day, candidates))
        day.forecasts = _forecasts(day, targets, seed, cache)
        pairs, alts = _boundaries(day, targets, candidates)
        choice = next_run(pairs, runs_left)
    statuses, p_confirm = _statuses(plan, pairs, choice)
    done = sum(p.confirmed for p in pairs)
    if choice.pair is None:
        reason = f"stop: no run raises the boundaries expected confirmed ({done} of {len(pairs)} confirmed)"
        return _result(day, None, reason, table, p_confirm, statuses)
    assert choice.side is not None and choice.option is not None
    alt = alts[choice.pair][choice.alternative]
    option = alt.options[choice.side][choice.option]
    if alt.new is not None:
        sid, reason = _new_pair_chosen(day, alt, choice.side, table)
        table = confirmation_table(plan, day.names, {**day.predicted, **_new_predictions(plan, alt)}, day.runs)
        statuses, p_confirm = _statuses(plan, pairs, choice)
    else:
        sid, reason = _chosen(day, alt.pair, choice.side, option)
    return _result(day, sid, reason, table, p_confirm, statuses)


def _statuses(plan: Plan, pairs: list[Pair], choice) -> tuple[dict[int, str], dict[int, float]]:
    """Per plan pair id: confirmed, open or lost, and its chance of confirmation by the day's end.  A boundary's
    pairs share its chance; a pair another replaced is lost, and a pair confirmed is certain."""
    status, p = {}, {}
    for b, pair in enumerate(_originals(plan)):
        members = [pair, *_replacements(plan, pair)]
        for k, q in enumerate(members):
            own = pairs[b].alternatives[k].own_confirmed  # the plan's pairs come first among the alternatives
            gone = choice.lost[b] or (k == 0 and len(members) > 1)
            status[int(q["id"])] = "confirmed" if own else "lost" if gone else "open"
            p[int(q["id"])] = 1.0 if own else 0.0 if gone else float(choice.p_confirm[b])
    return status, p


def _forecasts(day: Afternoon, targets: dict[str, Target], seed: int, cache: dict | None) -> SideForecasts:
    """The sides' forecasts in the plan's water, or with the afternoon's bias on top when the logs identify one
    and it foresaw the day's outcomes at least as well (:attr:`SideForecasts.evidence`)."""
    plan, record = day.plan, day.record
    flown = _flown(day, targets)
    sigma = plan_noise(plan)
    neutral = forecast_sides(plan.mission, targets, flown, sigma, (dict(NEUTRAL), record.sd, []), seed, cache)
    varied = [n for n in record.centre if record.identified(n)]
    day.bias_used = False
    if not varied or not flown:
        return neutral
    biased = forecast_sides(plan.mission, targets, flown, sigma, (record.bias().to_dict(), record.sd, varied), seed)
    if biased.evidence < neutral.evidence:
        return neutral
    day.bias_used = True
    return biased


def _side_target(day: Afternoon, pair: dict, sid: str) -> tuple[tuple[int, ...], tuple[float, ...]]:
    cols = outcome_columns(pair, day.names)
    return tuple(cols), tuple(float(v) for v in day.predicted[sid][cols])


def _targets(day: Afternoon) -> dict[str, Target]:
    """Every scenario flown for a pair side, with the side's outcome."""
    out = {}
    for pair in day.plan.pairs:
        for sid in pair["scenarios"]:
            cols, values = _side_target(day, pair, sid)
            for scen in side_scenarios(day.plan, sid):
                out[scen] = Target(day.plan.u(scen), cols, values)
    return out


def _showed(run: RunOutcome, t: Target) -> bool:
    return run.scores is not None and shows(run.scores, t.columns, t.values)


def _flown(day: Afternoon, targets: dict[str, Target]) -> list[tuple[str, bool]]:
    return [(r.sid, _showed(r, targets[r.sid])) for r in day.runs if r.sid in targets and r.scores is not None]


def _record(day: Afternoon, scen: str, t: Target) -> tuple[int, int]:
    ended = [r for r in day.runs if r.sid == scen and r.scores is not None]
    shown = sum(_showed(r, t) for r in ended)
    return shown, len(ended) - shown


def _moves(day: Afternoon, targets: dict[str, Target], seed: int, cache: dict) -> dict[str, Move]:
    """A candidate move for each side that missed and has no scenario likely to show on its next run."""
    assert day.forecasts is not None
    plan, fc = day.plan, day.forecasts
    mission = plan.mission
    if day.bias_used:
        mission = replace(mission, execution_bias=compose(mission.execution_bias, day.record.bias()))
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
            key = (sid, last, round(fc.scale, 1), day.bias_used)
            if key in cache:
                if cache[key] is not None:
                    out[sid] = cache[key]
                continue
            t = targets[last]
            dithers = fc.dithers.get(last)
            if dithers is None:  # a forecast kept in the day's record keeps no dithers: draw its own again
                drawn = forecast_sides(plan.mission, {last: t}, [], plan_noise(plan), (dict(NEUTRAL), {}, []), seed)
                dithers = drawn.dithers[last]
            assert dithers is not None
            outcome = Outcome(int(2 * t.values[0] + t.values[1]), t.columns, t.values)
            partner = plan.u(pair["scenarios"][1 - j])
            move = find_move(
                mission,
                plan.mission,
                sid,
                (last, plan.u(last)),
                partner,
                outcome,
                dithers,
                plan.sensitivity(),
                sigma,
                seed,
            )
            cache[key] = move
            if move is not None:
                out[sid] = move
    return out


@dataclass
class Alternative:
    """One pair across a boundary as the plan flies it: a plan pair, or a new pair not yet written (``new``);
    per side the options, each a scenario id or a move."""

    pair: dict
    options: list[list[str | Move]]
    new: NewPair | None = None


def _plan_alternative(day: Afternoon, pair: dict, targets: dict[str, Target]) -> tuple[Pair, Alternative]:
    assert day.forecasts is not None and day.moves is not None
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
    return Pair((sides[0], sides[1])), Alternative(pair, opts)


def _boundaries(
    day: Afternoon, targets: dict[str, Target], candidates: dict[int, list[NewPair]]
) -> tuple[list[Pair], list[list[Alternative]]]:
    """Per boundary (a plan pair generate chose): the pair as :mod:`rapt.confirmation` plans it, its replacements
    (the new pairs written for it today, then ``candidates``), and each alternative's options."""
    assert day.forecasts is not None
    plan = day.plan
    model: list[Pair] = []
    alternatives: list[list[Alternative]] = []
    for pair in _originals(plan):
        built = [_plan_alternative(day, q, targets) for q in [pair, *_replacements(plan, pair)]]
        pairs: list[Pair] = [b[0] for b in built]
        alts: list[Alternative] = [b[1] for b in built]
        for k, new in enumerate(candidates.get(int(pair["id"]), [])):
            ids = [_candidate_id(new, k, side) for side in "ab"]
            pairs.append(Pair((Side((Option(day.forecasts.p[ids[0]]),)), Side((Option(day.forecasts.p[ids[1]]),)))))
            alts.append(Alternative(pair, [[ids[0]], [ids[1]]], new))
        model.append(replace(pairs[0], replacements=tuple(pairs[1:])))
        alternatives.append(alts)
    return model, alternatives


def _originals(plan: Plan) -> list[dict]:
    """The plan's boundaries: the pairs generate chose (not the new ones next wrote)."""
    return [p for p in plan.pairs if "origin" not in p]


def _replacements(plan: Plan, pair: dict) -> list[dict]:
    return [p for p in plan.pairs if p.get("origin", {}).get("replaces") == pair["id"]]


def _candidate_id(new: NewPair, k: int, side: str) -> str:
    """A forecast's name for side ``side`` of the ``k``-th new pair offered for pair ``new.replaces``."""
    return f"new{new.replaces}.{k}{side}"


def _candidates(day: Afternoon, lost: list[int]) -> dict[int, list[NewPair]]:
    """For each lost boundary, the noon study's other pairs across it not yet written into the plan."""
    plan, out = day.plan, {}
    written = [plan.u(s) for p in plan.pairs for s in p["scenarios"]]
    for pid in lost:
        pair = next(p for p in plan.pairs if int(p["id"]) == pid)
        found = []
        for rows in (day.record.alternatives or {}).get(str(pid), []):
            new = candidate(plan, pair, rows, day.names)
            if new is not None and not any(np.allclose(new.U[0], w) for w in written):
                found.append(new)
        if found:
            out[pid] = found
    return out


def _candidate_targets(day: Afternoon, candidates: dict[int, list[NewPair]]) -> dict[str, Target]:
    plan, out = day.plan, {}
    for pid, news in candidates.items():
        cols = outcome_columns(next(p for p in plan.pairs if int(p["id"]) == pid), day.names)
        for k, new in enumerate(news):
            for s, side in enumerate("ab"):
                out[_candidate_id(new, k, side)] = Target(
                    new.U[s], tuple(cols), tuple(float(v) for v in new.scores[s][cols])
                )
    return out


def _chosen(day: Afternoon, pair: dict, j: int, option: str | Move) -> tuple[str, str]:
    """The scenario to fly (a move written into the plan first) and the one-line reason."""
    plan, fc = day.plan, day.forecasts
    assert fc is not None
    sid = pair["scenarios"][j]
    cols, values = _side_target(day, pair, sid)
    want = mode_name(target_scores(list(cols), np.asarray(values)))
    who = f"pair {pair['id']}'s {SIDE_NAMES[j]} side"
    side_runs = [r for r in day.runs if r.sid in side_scenarios(plan, sid) and r.scores is not None]
    if isinstance(option, Move):
        vid = variant_id(plan, sid)
        reason = (
            f"{who} {_came_out(day, side_runs[-1], cols, values)}; moved {option.sigmas:g}σ in "
            f"{option.parameter} as {vid} (P(shows {want}) {option.p:.2f})"
        )
        add_variant(plan, option, vid, reason, [r.log for r in day.runs], day.record.bias().to_dict())
        return vid, reason
    scen = option
    shown, missed = _record(day, scen, Target(plan.u(scen), cols, values))
    p = Option(fc.p[scen], shown, missed).p_next
    if not side_runs:
        return scen, f"{who} not flown yet: fly {scen} (P(shows {want}) {p:.2f})"
    came_out = _came_out(day, side_runs[-1], cols, values)
    if shown + missed == 0:
        return scen, f"{who} {came_out}; fly its variant {scen} (P(shows {want}) {p:.2f})"
    return scen, f"{who}: {shown} of {shown + missed} runs of {scen} showed {want}; fly it again (P(shows) {p:.2f})"


def _new_pair_chosen(day: Afternoon, alt: Alternative, j: int, table: list[dict]) -> tuple[str, str]:
    """A new pair written into the plan for a boundary that fell through; its side ``j`` to fly, and the reason."""
    assert alt.new is not None and day.forecasts is not None
    old = alt.pair
    p_sides = [day.forecasts.p[str(side[0])] for side in alt.options]  # this candidate's sides, as forecast
    row = next(r for r in table if r["id"] == old["id"])
    why = "; ".join(f"its {side} side {r['status']}" for side, r in zip("ab", row["sides"]))
    n = new_pair_id(day.plan)
    sid = f"pair{n}{'ab'[j]}"
    reason = (
        f"pair {old['id']}'s boundary ({', '.join(old.get('elements', []))}) fell through ({why}, no move holds "
        f"with the runs left); new pair {n} across it from the noon study, {alt.new.distance:.3f} apart: "
        f"fly {sid} (P(shows) {p_sides[j]:.2f})"
    )
    add_pair(day.plan, alt.new, day.names, reason, [r.log for r in day.runs], p_sides)
    return sid, reason


def _new_predictions(plan: Plan, alt: Alternative) -> dict[str, np.ndarray]:
    """The predicted scores of the new pair just written (the plan's last pair)."""
    assert alt.new is not None
    return dict(zip(plan.pairs[-1]["scenarios"], alt.new.scores))


def _came_out(day: Afternoon, run: RunOutcome, cols: tuple[int, ...], values: tuple[float, ...]) -> str:
    """How the side's last run differed from its outcome: its mode, else the first element that differed."""
    got, want = _scores(run), mode_name(target_scores(list(cols), np.asarray(values)))
    if mode_name(got) != want:
        return f"came out {mode_name(got)}, predicted {want}"
    for c, v in zip(cols, values):
        if got[c] != v:
            return f"came out {want} but {day.names[c]} {got[c]:g}, predicted {v:g}"
    return f"came out {want} as predicted"


def _scores(run: RunOutcome) -> np.ndarray:
    assert run.scores is not None  # runs with an end only
    return run.scores


def _result(
    day: Afternoon, sid: str | None, reason: str, table: list[dict], p_confirm: dict[int, float], status: dict[int, str]
) -> dict:
    pairs = []
    for p in table:
        row = {"id": p["id"], "status": status[int(p["id"])], "p_confirm": round(float(p_confirm[int(p["id"])]), 4)}
        if "replaces" in p:
            row["replaces"] = p["replaces"]
        pairs.append(row)
    fc = day.forecasts
    return {
        "next": None if sid is None else {"scenario": sid, "plan": str(day.plan.path)},
        "reason": reason,
        "pairs": pairs,
        "confirmation": table,
        "forecast": None if fc is None else {**fc.to_dict(), "p_shows": {k: round(v, 4) for k, v in fc.p.items()}},
        "bias": {
            "centre": day.record.bias().to_dict(),
            "identified": [n for n in day.record.sd if day.record.identified(n)],
            "used": day.bias_used,
        },
        "logs": len(day.runs),
    }
