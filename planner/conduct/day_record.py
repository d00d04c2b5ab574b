"""What the afternoon has learnt so far, kept beside the plan so each ``rapt-plan next`` adds only the new logs.

``afternoon.json`` in the plan directory holds, per log read (keyed by its resolved path, size
and modification time), the scenario it flew, its scores and whether its automatic checks
passed; and the day's bias posterior, updated by the logs not yet in it.  A log is read once:
a call with ten logs of which one is new reads one (a log is the costly part, about a second
each, and its bias fit a few more).

The bias is updated as a sequential Bayesian fit (:func:`update_bias`): the previous posterior
(centre and s.d. per parameter, neutral and :data:`planner.review.biasfit.PRIOR_SD` at the start
of the afternoon; the plan's mission already carries the noon's bias) is the prior of a MAP fit
(:func:`planner.review.biasfit.fit_bias`) to the new logs only.  A parameter the new logs identify
takes their estimate and s.e. (never under :data:`SD_FLOOR` of the prior's); the others keep their posterior.  Correlations between parameters
are dropped from one update to the next: each is carried as its own Gaussian.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from planner.common.atomic import write_text_atomic
from planner.common.plans import Plan
from planner.review.biasfit import PRIOR_SD, fit_bias
from planner.review.logs import LoggedRun, read_run
from planner.review.run_checks import verdict_of
from planner.review.runs import match_logs, score_observed
from sim.uuv.bias import BIAS_NAMES, NEUTRAL, Bias
from sim.uuv.scenario import make_scenarios

__all__ = ["RECORD_NAME", "LogRecord", "DayRecord", "load_record", "read_logs", "update_bias", "log_key"]

RECORD_NAME = "afternoon.json"
#: The posterior s.d. never falls below this share of the prior's: a log's Laplace s.e. is optimistic
#: (its residuals move together), and a later log must still be able to move the estimate.
SD_FLOOR = 0.1
#: The afternoon bias is used where its posterior s.d. is below this share of its prior's (identified).
IDENTIFIED_BELOW = 0.5


def log_key(path: Path) -> str:
    """A log's identity: its resolved path, size and modification time (a log flown again is a new log)."""
    st = path.stat()
    return f"{path.resolve()}|{st.st_size}|{st.st_mtime_ns}"


@dataclass
class LogRecord:
    """One log as the afternoon needs it."""

    path: str
    scenario: str
    scores: list[float] | None  # None: the run's end is not in the log
    checks_passed: bool

    def to_dict(self) -> dict:
        return {
            "path": self.path,
            "scenario": self.scenario,
            "scores": self.scores,
            "checks_passed": self.checks_passed,
        }


@dataclass
class DayRecord:
    """The logs read this afternoon and the bias posterior after them."""

    plan_id: str
    logs: dict[str, LogRecord] = field(default_factory=dict)
    bias_logs: list[str] = field(default_factory=list)  # keys of the logs the posterior has seen
    centre: dict[str, float] = field(default_factory=lambda: dict(NEUTRAL))
    sd: dict[str, float] = field(default_factory=lambda: dict(PRIOR_SD))
    #: the forecasts in the plan's water (no afternoon bias), by scenario: P(shows) per noise scale; they depend
    #: on the plan and the seed only, so they are drawn once an afternoon (``forecast_seed`` says for which seed)
    forecasts: dict[str, tuple] = field(default_factory=dict)
    forecast_seed: int | None = None
    #: per plan pair id, the noon study's other pairs across its boundary (unit rows; None: not read yet)
    alternatives: dict[str, list] | None = None

    def bias(self) -> Bias:
        """The afternoon's bias: each identified parameter's posterior centre, the others neutral."""
        return Bias(**{n: self.centre[n] if self.identified(n) else NEUTRAL[n] for n in BIAS_NAMES})

    def identified(self, name: str) -> bool:
        return self.sd[name] < IDENTIFIED_BELOW * PRIOR_SD[name]

    def to_dict(self) -> dict:
        return {
            "plan_id": self.plan_id,
            "logs": {k: r.to_dict() for k, r in self.logs.items()},
            "bias": {"logs": self.bias_logs, "centre": self.centre, "sd": self.sd},
            "forecasts": {
                "seed": self.forecast_seed,
                "p_by_scale": {s: [float(x) for x in v[0]] for s, v in self.forecasts.items()},
            },
            "alternatives": self.alternatives,
        }

    def save(self, directory: Path) -> None:
        write_text_atomic(directory / RECORD_NAME, json.dumps(self.to_dict(), indent=1))


def load_record(directory: Path, plan: Plan) -> DayRecord:
    """The plan directory's record, or a fresh one (no record, a damaged one, or one of another plan)."""
    path = directory / RECORD_NAME
    try:
        data = json.loads(path.read_text())
        if data.get("plan_id") != plan.id:
            return DayRecord(plan.id)
        logs = {k: LogRecord(**v) for k, v in data["logs"].items()}
        b = data["bias"]
        f = data.get("forecasts") or {}
        drawn = {sid: (np.asarray(p, dtype=float), None) for sid, p in (f.get("p_by_scale") or {}).items()}
        return DayRecord(
            plan.id,
            logs,
            list(b["logs"]),
            {**NEUTRAL, **b["centre"]},
            {**PRIOR_SD, **b["sd"]},
            drawn,
            f.get("seed"),
            data.get("alternatives"),
        )
    except (OSError, ValueError, KeyError, TypeError):
        return DayRecord(plan.id)


def read_logs(plan: Plan, paths: list[Path], record: DayRecord) -> tuple[list[str], dict[str, LoggedRun]]:
    """The keys of ``paths`` in order, and the logs not in ``record`` read, matched to the plan and scored.

    Raises (one line naming the log) for a log of another plan or mission or of a scenario the plan does not
    know, before anything is recorded; the caller adds the new ones to ``record`` with :func:`remember`.
    """
    keys = [log_key(p) for p in paths]
    new = {k: p for k, p in zip(keys, paths) if k not in record.logs}
    runs = {k: read_run(p) for k, p in new.items()}
    obs = match_logs(plan, list(runs.values()))
    score_observed(plan.mission, obs)
    for k, o in zip(runs, obs):
        record.logs[k] = LogRecord(
            str(o.run.path),
            o.sid,
            None if o.mode is None or o.scores is None else [float(v) for v in np.asarray(o.scores)],
            verdict_of(o.run.checks) != "fail",
        )
    return keys, runs


def update_bias(plan: Plan, record: DayRecord, keys: list[str], runs: dict[str, LoggedRun]) -> list[str]:
    """Fold the logs of ``keys`` the posterior has not seen into it (module docstring); the keys folded in.

    A call whose logs leave out one the posterior has seen starts the afternoon's posterior again from
    the logs given (they are then all read).  Runs whose checks failed, or with no replayable flight, are
    not fitted.
    """
    if not set(record.bias_logs) <= set(keys):
        record.bias_logs, record.centre, record.sd = [], dict(NEUTRAL), dict(PRIOR_SD)
    todo = [k for k in keys if k not in record.bias_logs and record.logs[k].checks_passed]
    if not todo:
        return []
    m = plan.mission
    flights = [runs[k] if k in runs else read_run(Path(record.logs[k].path)) for k in todo]
    usable = [(k, r) for k, r in zip(todo, flights) if r.steps.shape[0] > 0]
    if usable:
        starts = [float(make_scenarios(m, plan.u(record.logs[k].scenario)[None, :]).start_time[0]) for k, _ in usable]
        priors = {n: (record.centre[n], record.sd[n]) for n in BIAS_NAMES}
        try:
            fit = fit_bias(m, [r for _, r in usable], starts, bootstrap=0, priors=priors)
        except ValueError:  # no replayable segment in these logs: nothing to learn from them
            fit = None
        if fit is not None:
            for n in fit.fitted:
                if fit.estimate.identified[n]:
                    record.centre[n] = float(fit.estimate.value[n])
                    floor = SD_FLOOR * PRIOR_SD[n]
                    record.sd[n] = float(max(min(fit.estimate.stderr[n], record.sd[n]), floor))
    record.bias_logs += todo
    return todo
