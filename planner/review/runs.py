"""The two sides of a comparison: the logged runs, each matched to its plan scenario, and the plan's runs.

:func:`match_logs` finds each log's plan scenario by the scenario record it carries
(:mod:`planner.common.scenario_record`) and refuses a log of another mission or plan;
:func:`score_observed` scores its track with the mission's own scorer.  :func:`predict_plan`
simulates every plan scenario as planned (and checks the plan still predicts what it says);
:class:`PlanRuns` holds those runs beside the ones under the fitted bias.  :class:`CompareConfig`
is the comparison's settings, read by every step of :func:`planner.review.compare.compare`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

import sim.uuv
from planner.common.plans import Plan
from planner.review.logs import LogError, LoggedRun
from rapt.errors import StudyMismatchError
from sim.uuv.bias import BIAS_NAMES
from sim.uuv.mission import Vehicle
from sim.uuv.replay import score_track
from sim.uuv.scoring import MODE_NAMES, mode_name

__all__ = ["CompareConfig", "Observation", "match_logs", "score_observed", "PlanRuns", "row_index", "predict_plan"]


@dataclass
class CompareConfig:
    """The settings of a comparison (``rapt-plan compare``'s options)."""

    dithers: int = 20  # stochastic runs checking each adjusted scenario (0: none)
    seed: int = 0
    fit: tuple[str, ...] = BIAS_NAMES  # bias parameters to fit; the others stay neutral
    p_target: float = 0.8
    bootstrap: int = 20  # block-bootstrap refits for the standard errors (0: analytic only)
    plant: Vehicle | None = None  # a calibrated vehicle (rapt-plan calibrate): flown in every prediction
    draws: int = 100  # Monte-Carlo runs per scenario of each forecast (planner.review.forecast)
    keep_failed: bool = False  # count runs whose automatic checks failed in the bias fit (planner.review.run_checks)


@dataclass
class Observation:
    """One logged run matched to its plan scenario ``sid`` (row ``u``); its scores and mode once scored."""

    run: LoggedRun
    sid: str
    u: np.ndarray
    scores: np.ndarray | None = None
    mode: str | None = None  # None: the run's end is not in the log
    notes: list[str] = field(default_factory=list)


def match_logs(plan: Plan, runs: list[LoggedRun]) -> list[Observation]:
    """Each log's plan scenario, by its metadata; LogError naming the log that does not belong."""
    out = []
    for run in runs:
        meta, name = run.meta, run.path.name
        mission = meta.get("mission")
        if mission != plan.mission.name:
            raise LogError(
                f"LOG: {name} was flown on mission {mission!r}, but the plan is for "
                f"{plan.mission.name!r}; compare a plan only with the logs of its own runs"
            )
        pid = meta.get("plan_id") or ""
        if pid and pid != plan.id:
            raise LogError(
                f"LOG: {name} flew plan {pid}, not this plan ({plan.id}); give the plan directory "
                "its runs were flown from"
            )
        u = np.asarray(meta.get("u", []), dtype=float)
        sid = str(meta.get("scenario_id", ""))
        known = {s["id"]: np.asarray(s["u"], dtype=float) for s in plan.scenarios + plan.variants}
        if sid not in known or u.shape != known[sid].shape or not np.allclose(u, known[sid], rtol=0, atol=1e-9):
            same = [k for k, v in known.items() if u.shape == v.shape and np.allclose(u, v, rtol=0, atol=1e-9)]
            if not same:
                raise LogError(
                    f"LOG: {name} flew scenario {sid!r}, which is not a scenario of this plan (no plan "
                    "scenario has its parameters); fly it with rapt-plan run PLAN/plan.json --scenario ID"
                )
            sid = same[0]
        out.append(Observation(run, sid, known[sid]))
    return out


def score_observed(m, obs: list[Observation]) -> None:
    """Each logged run's scores from its track, and its mode when the run's end is in the log."""
    for o in obs:
        if o.run.steps.shape[0]:
            o.scores = score_track(m, o.u, o.run.track, o.run.wp_aborted, o.run.return_reason)
            if o.run.has_end:
                o.mode = mode_name(o.scores)


@dataclass
class PlanRuns:
    """Every plan scenario (and variant): its unit-cube row, its run as planned and under the fitted bias
    (both simulated with their trajectories)."""

    ids: list[str]
    U: np.ndarray
    pred: sim.uuv.Result
    corr: sim.uuv.Result
    calib: sim.uuv.Result | None = None  # with the calibrated vehicle, no bias (when one is given)

    @cached_property
    def row_of(self) -> dict[str, int]:
        """The row of each scenario id."""
        return row_index(self.ids)

    def trajectories(self, sid: str) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Scenario ``sid``'s predicted and corrected trajectories (None when it is invalid)."""
        k = self.row_of[sid]
        return self.pred.trajectory(k), self.corr.trajectory(k)

    def calibrated_trajectory(self, sid: str) -> np.ndarray | None:
        """Scenario ``sid``'s trajectory with the calibrated vehicle (None without one, or when invalid)."""
        return None if self.calib is None else self.calib.trajectory(self.row_of[sid])


def row_index(ids: list[str]) -> dict[str, int]:
    """The row of each scenario id in ``ids``."""
    return {sid: k for k, sid in enumerate(ids)}


def predict_plan(plan: Plan) -> tuple[list[str], np.ndarray, sim.uuv.Result]:
    """Predictions of every plan scenario, unbiased, as planned: ids, unit-cube rows and the runs (with
    trajectories); StudyMismatchError when they are not the plan's."""
    m = plan.mission
    ids = [s["id"] for s in plan.scenarios + plan.variants]
    U_plan = np.array([plan.u(i) for i in ids]).reshape(-1, m.dim)
    pred = sim.uuv.simulate(m, U_plan, trajectories=True)
    row_of = row_index(ids)
    for s in plan.scenarios + plan.variants:
        planned = s.get("predicted", {}).get("mode")
        got = MODE_NAMES[pred.modes[row_of[s["id"]]]] if pred.valid[row_of[s["id"]]] else "invalid"
        if planned and planned != got:
            raise StudyMismatchError(
                f"PLAN: scenario {s['id']} is predicted {got} by {plan.mission.source} but the plan says "
                f"{planned}; the mission or the simulator changed since the plan was made — regenerate the plan"
            )
    return ids, U_plan, pred
