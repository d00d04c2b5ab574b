"""Train, keep and reuse a surrogate of a mission's back-seat autonomy (chapter 6).

:func:`train_surrogate` runs Q-DAgger (or DAgger, or behavioural cloning) against the
batch simulator's expert on random valid scenarios of the mission and returns a
:class:`~sim.uuv.imitation.surrogate.Surrogate`; :func:`load_or_train` reuses a saved one
when it was trained for this very mission and trains (and saves) one otherwise.  The
expert-run counts it records are what the surrogate workflow of ``rapt-plan generate
--surrogate`` spends on training.

How often a policy ends scenarios in the expert's mode (:func:`policy_mode_agreement`) is
what judges it, both while training (the held-out runs choose the update kept) and after
each update (:class:`ModeValidation`, for ``rapt-plan surrogate --validate N``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.stats import qmc

import sim.uuv
from planner.plan.surrogate_training import DIRECTED_FROM, HeldOutPairs, directed_rollout
from rapt.errors import InputError
from rapt.imitation.dagger import IterationRecord, imitate
from rapt.imitation.policies import Policy
from sim.uuv.imitation.features import GOAL, feature_spec, policy_heads
from sim.uuv.imitation.rollouts import make_rollout
from sim.uuv.imitation.surrogate import Surrogate
from sim.uuv.mission import Mission

__all__ = [
    "train_surrogate",
    "load_or_train",
    "calibrate_goal_threshold",
    "mode_agreement",
    "policy_mode_agreement",
    "ModeValidation",
    "TRAINING_DEFAULTS",
    "GOAL_THRESHOLDS",
]

#: Goal thresholds tried on the held-out expert runs (the goal output is about -1 or +1).
GOAL_THRESHOLDS = tuple(round(t, 1) for t in np.arange(-0.9, 0.91, 0.1))

#: Section 6.6.1's budget: 250 expert runs, 200 annotated (10 per update) and 50 held out.
TRAINING_DEFAULTS = {
    "method": "qdagger",
    "quantile": 0.5,
    "runs": 200,
    "runs_per_iteration": 10,
    "epochs": 30,
    "mixing": 0.5,
    "select_runs": 50,
    "directed": True,
    "directed_share": 0.5,
}


def train_surrogate(
    mission: Mission,
    *,
    method: str = "qdagger",
    quantile: float = 0.5,
    runs: int = 200,
    runs_per_iteration: int = 10,
    epochs: int = 30,
    mixing: float = 0.5,
    select_runs: int = 50,
    seed: int = 0,
    on_iteration: Callable[[IterationRecord, Policy], None] | None = None,
    goal_classifier: bool = True,
    observation: str = "contacts",
    directed: bool = True,
    directed_share: float = 0.5,
) -> Surrogate:
    """Imitate the mission's expert with ``runs`` annotated runs (``runs_per_iteration`` at a time).

    ``mixing`` p: update i's runs obey the expert on a share p**i of their steps (DAgger's
    beta; 0 follows Algorithm 9 to the letter, the learner flying every step from update 1).
    ``directed``: from the third update on, a ``directed_share`` of the annotated runs are the
    learner's boundary candidates and disagreements (the rest drawn uniformly), and the ``select_runs`` held-out expert runs are pairs of
    them (:mod:`planner.plan.surrogate_training`): the update kept is the one that reproduces
    most of the expert's held-out boundary pairs, type by type.  Otherwise the runs and the
    held-out runs are drawn uniformly and the update kept has the best mode accuracy on them
    (0 held-out runs keep the last).  The held-out runs then set the goal threshold
    (:func:`calibrate_goal_threshold`).  The surrogate's ``training["runs"]`` counts every
    expert run spent: annotated and held out.  ``goal_classifier`` trains the goal decision
    as a classifier weighted toward the expert's switches (:func:`rapt.imitation.dagger.imitate`'s
    ``decisions``); False regresses it on +-1 like the velocity, for comparison.
    """
    _check_training(runs, runs_per_iteration, mixing, select_runs)
    spec = feature_spec(mission, observation)
    held = _HeldOut(mission, spec, int(select_runs), seed, directed)
    flown: list[np.ndarray] = []  # the scenarios the expert annotated, iteration by iteration
    rollout = (
        directed_rollout(mission, spec, seed=seed, mixing=mixing, share=directed_share, record=flown)
        if directed
        else make_rollout(mission, spec, seed=seed, mixing=mixing, record=flown)
    )
    result = imitate(
        rollout,
        method=method,
        quantile=quantile,
        iterations=runs // runs_per_iteration - 1,
        runs_per_iteration=runs_per_iteration,
        epochs=epochs,
        seed=seed,
        select=held.score if select_runs else None,
        on_iteration=on_iteration,
        heads=policy_heads(spec),
        decisions=[GOAL] if goal_classifier else [],
        decided_where=spec.waypoint_pending,
    )
    h = result.history[result.chosen]
    threshold, calibration = 0.0, None
    if select_runs:
        threshold, share = calibrate_goal_threshold(result.policy, spec, held.trajectories)
        calibration = [round(a, 4) for a in share]
    training = {
        "method": f"{method}({int(round(quantile * 100))})" if method.startswith("qdagger") else method,
        "observation": observation,
        "directed": float(directed_share) if directed else 0.0,
        "runs": result.runs + int(select_runs),
        "annotated_runs": result.runs,
        "select_runs": int(select_runs),
        "held_out_boundary_pairs": held.boundary_pairs,
        "chosen_iteration": result.chosen,
        "selection": h.extra.get("selection"),
        "samples": h.samples,
        "seed": seed,
        "epochs": epochs,
        "mixing": mixing,
        "goal": "classifier" if goal_classifier else "regression",
        "fit_s": round(sum(r.fit_s for r in result.history), 2),
        "train_s": round(result.history[-1].elapsed_s, 2),
        "iterations": len(result.history),
        "threshold_reproduced": calibration,
        # every scenario the expert flew for this surrogate (unit cube): annotated, then held out
        "expert_scenarios": np.vstack(flown + ([held.X] if held.X is not None else [])).tolist(),
    }
    return Surrogate.for_mission(mission, result.policy, training, threshold, observation)


def _check_training(runs: int, runs_per_iteration: int, mixing: float, select_runs: int) -> None:
    """:func:`train_surrogate`'s options, checked before any run is flown."""
    if not 0.0 <= mixing < 1.0:
        raise InputError(f"--mixing: expected a share in [0, 1), got {mixing!r}")
    if int(runs_per_iteration) != runs_per_iteration or runs_per_iteration < 1:
        raise InputError(f"--runs-per-iteration: expected a positive whole number, got {runs_per_iteration!r}")
    if int(runs) != runs or runs < runs_per_iteration:
        raise InputError(f"--runs: expected at least {runs_per_iteration} annotated runs, got {runs!r}")
    if int(select_runs) != select_runs or select_runs < 0:
        raise InputError(f"--select-runs: expected a number of held-out expert runs >= 0, got {select_runs!r}")


class _HeldOut:
    """The held-out expert runs that choose the update kept: boundary pairs of the learner's
    candidates, drawn once its search can show some (``directed``), else uniform draws."""

    def __init__(self, mission: Mission, spec, runs: int, seed: int, directed: bool):
        self.mission, self.spec, self.runs, self.seed, self.directed = mission, spec, runs, seed, directed
        self.calls = 0
        self.X: np.ndarray | None = None
        self.pairs: HeldOutPairs | None = None
        self.trajectories: list = []
        self.boundary_pairs: int | None = None
        if runs and not directed:
            self.pairs = HeldOutPairs.uniform(mission, spec, runs, seed)
            self.trajectories, self.X = self.pairs.trajectories, self.pairs.X

    def score(self, policy: Policy) -> tuple[float, ...]:
        """Higher is better; updates before the held-out pairs exist are never kept.  Uniform held-out runs
        hold no pairs: (mode accuracy, minus the path error)."""
        self.calls += 1
        if not self.directed:
            assert self.pairs is not None, "drawn when the runs are uniform"
            return self.pairs(policy)[1:]
        if self.pairs is None and self.calls < DIRECTED_FROM:
            return (-np.inf,)
        if self.pairs is None:
            self.pairs = HeldOutPairs.around(self.mission, self.spec, policy, self.runs, self.seed * 1000 + 0x5E1)
            self.trajectories, self.X = self.pairs.trajectories, self.pairs.X
            self.boundary_pairs = int(self.pairs.boundary_pairs().shape[0])
        return self.pairs(policy)


def calibrate_goal_threshold(
    policy, spec, trajectories, thresholds=GOAL_THRESHOLDS, within_steps: int = 5
) -> tuple[float, list[float]]:
    """The goal threshold under which ``policy`` gives the waypoint up where the expert did.

    Why: the expert gives its waypoint up once per aborted run, so among the many states beside
    a pending waypoint a +1 goal label is rare, and a regression on +-1 learns an output that
    crosses 0 late.  On held-out expert runs
    (``trajectories`` of :func:`~sim.uuv.imitation.rollouts.annotated_runs`, the expert flying), a
    run counts as reproduced under a threshold when the goal output first exceeds it at most
    ``within_steps`` steps before the expert's turn (or never, if the expert never turned).
    Every run weighs in, not only the few whose mode a threshold flips.  Ties go to the middle
    of the best thresholds.  Returns (threshold, share of runs reproduced per threshold).
    """
    thresholds = np.asarray(thresholds, float)
    hits = np.zeros(thresholds.size)
    runs = 0
    for t in trajectories:
        pending = np.flatnonzero(spec.waypoint_pending(t.features))
        if pending.size == 0:
            continue
        runs += 1
        goal = policy(t.features[pending], quiet=spec.quiet)[:, GOAL]
        turned = np.flatnonzero(t.expert[pending, GOAL] > 0)
        above = goal[:, None] > thresholds[None, :]
        first = np.where(above.any(axis=0), above.argmax(axis=0), -1)
        if turned.size:
            hits += (first >= 0) & (first >= turned[0] - within_steps) & (first <= turned[0])
        else:
            hits += first < 0
    share = (hits / max(runs, 1)).tolist()
    best = np.flatnonzero(np.isclose(share, max(share)))
    return float(thresholds[int(best[len(best) // 2])]), share


def load_or_train(path: Path, mission: Mission, seed: int = 0, on_iteration=None, **options) -> tuple[Surrogate, bool]:
    """The surrogate saved at ``path`` (refused unless trained for ``mission``), or a new one saved there.

    Returns (surrogate, trained_now).
    """
    path = Path(path)
    if path.exists():
        return Surrogate.load(path, mission), False
    if path.suffix != ".npz":
        raise InputError(f"--surrogate: a surrogate file ends in .npz, got {str(path)!r}")
    sur = train_surrogate(mission, seed=seed, on_iteration=on_iteration, **{**TRAINING_DEFAULTS, **options})
    sur.save(path)
    return sur, True


def mode_agreement(mission: Mission, surrogate: Surrogate, X: np.ndarray, expert=None) -> float:
    """Share of the valid scenarios ``X`` where the surrogate shows the expert's mode."""
    expert = sim.uuv.simulate(mission, X) if expert is None else expert
    mine = sim.uuv.simulate(mission, X, surrogate=surrogate)
    ok = expert.valid & mine.valid
    return float(np.mean(mine.modes[ok] == expert.modes[ok])) if ok.any() else float("nan")


def policy_mode_agreement(
    mission: Mission, policy: Policy, X: np.ndarray, expert=None, observation: str = "contacts"
) -> float:
    """:func:`mode_agreement` of ``policy`` (as a surrogate of ``mission``, default threshold) on ``X``."""
    return mode_agreement(mission, Surrogate.for_mission(mission, policy, observation=observation), X, expert)


class ModeValidation:
    """``n`` Sobol scenarios of ``mission`` (seeded), flown once by the expert; call it with a policy.

    ``rapt-plan surrogate --validate N`` reports after each imitation update the mode
    accuracy of the policy so far.  The validation scenarios (the first N of a Sobol
    sequence) and the expert's runs on them are drawn once, so every update is measured on
    the same ground and the expert is not flown again.
    """

    def __init__(self, mission: Mission, n: int, seed: int = 0, observation: str = "contacts"):
        self.mission, self.observation = mission, observation
        self.X: np.ndarray = qmc.Sobol(mission.dim, seed=seed).random(n)
        self.expert = sim.uuv.simulate(mission, self.X)

    def __call__(self, policy: Policy) -> float:
        """Share of the valid validation scenarios where ``policy`` flies into the expert's mode."""
        return policy_mode_agreement(self.mission, policy, self.X, self.expert, self.observation)
