"""Train, keep and reuse a surrogate of a mission's back-seat autonomy (chapter 6).

:func:`train_surrogate` runs Q-DAgger (or DAgger, or behavioural cloning) against the
batch simulator's expert on random valid scenarios of the mission and returns a
:class:`~sim.imitation.surrogate.Surrogate`; :func:`load_or_train` reuses a saved one
when it was trained for this very mission and trains (and saves) one otherwise.  The
expert-run counts it records are what the surrogate workflow of ``rapt-plan generate
--surrogate`` spends on training.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

import sim
from rapt.imitation import IterationRecord, MLPPolicy, imitate
from sim.imitation.features import feature_spec, policy_heads
from sim.imitation.rollouts import draw_valid, make_rollout
from sim.imitation.surrogate import Surrogate
from sim.mission import Mission
from sim.scenario import make_scenarios
from sim.scoring import modes_from_scores
from sim.simulate import run_scenarios

__all__ = ["train_surrogate", "load_or_train", "calibrate_goal_threshold", "TRAINING_DEFAULTS", "GOAL_THRESHOLDS"]

#: Goal thresholds tried on the held-out expert runs (the goal output is about -1 or +1).
GOAL_THRESHOLDS = tuple(round(t, 1) for t in np.arange(-0.9, 0.91, 0.1))

#: Section 6.6.1: 5 expert runs, then 5 annotated runs per iteration; 50-75 runs converge.
TRAINING_DEFAULTS = {"method": "qdagger", "quantile": 0.5, "runs": 75, "runs_per_iteration": 5, "epochs": 30,
                     "mixing": 0.5, "select_runs": 50}


def train_surrogate(mission: Mission, *, method: str = "qdagger", quantile: float = 0.5, runs: int = 75,
                    runs_per_iteration: int = 5, epochs: int = 30, mixing: float = 0.5, select_runs: int = 50,
                    seed: int = 0,
                    on_iteration: Callable[[IterationRecord, MLPPolicy], None] | None = None) -> Surrogate:
    """Imitate the mission's expert with ``runs`` annotated runs (``runs_per_iteration`` at a time).

    ``mixing`` p: update i's runs obey the expert on a share p**i of their steps (DAgger's
    beta; 0 follows Algorithm 9 to the letter, the learner flying every step from update 1).
    ``select_runs`` held-out expert runs choose the update whose policy is kept (the best
    mode accuracy on them; 0 keeps the last), then its goal threshold
    (:func:`calibrate_goal_threshold`).  The surrogate's ``training["runs"]`` counts every
    expert run spent: annotated and held out.
    """
    if not 0.0 <= mixing < 1.0:
        raise ValueError(f"--mixing: expected a share in [0, 1), got {mixing!r}")
    if int(runs_per_iteration) != runs_per_iteration or runs_per_iteration < 1:
        raise ValueError(f"--runs-per-iteration: expected a positive whole number, got {runs_per_iteration!r}")
    if int(runs) != runs or runs < runs_per_iteration:
        raise ValueError(f"--runs: expected at least {runs_per_iteration} annotated runs, got {runs!r}")
    if int(select_runs) != select_runs or select_runs < 0:
        raise ValueError(f"--select-runs: expected a number of held-out expert runs >= 0, got {select_runs!r}")
    spec = feature_spec(mission)
    select = None
    if select_runs:
        Xs = draw_valid(mission, int(select_runs), np.random.default_rng([int(seed), 0x73656C]))
        expert = sim.simulate(mission, Xs)
        select = lambda policy: mode_agreement(mission, Surrogate.for_mission(mission, policy), Xs, expert)  # noqa: E731
    result = imitate(make_rollout(mission, spec, seed=seed, mixing=mixing), method=method, quantile=quantile,
                     iterations=runs // runs_per_iteration - 1, runs_per_iteration=runs_per_iteration,
                     epochs=epochs, seed=seed, select=select, on_iteration=on_iteration,
                     heads=policy_heads(spec))
    h = result.history[result.chosen]
    threshold, calibration = 0.0, None
    if select_runs:
        threshold, accuracy = calibrate_goal_threshold(mission, Surrogate.for_mission(mission, result.policy), Xs,
                                                       expert)
        calibration = [round(a, 4) for a in accuracy]
    training = {"method": method if method != "qdagger" else f"qdagger({int(round(quantile * 100))})",
                "runs": result.runs + int(select_runs), "annotated_runs": result.runs,
                "select_runs": int(select_runs), "chosen_iteration": result.chosen,
                "selection_accuracy": h.extra.get("selection"), "samples": h.samples, "seed": seed,
                "epochs": epochs, "mixing": mixing, "fit_s": round(sum(r.fit_s for r in result.history), 2),
                "iterations": len(result.history), "goal_threshold": threshold,
                "threshold_accuracy": calibration}
    return Surrogate.for_mission(mission, result.policy, training, threshold)


def calibrate_goal_threshold(mission: Mission, surrogate: Surrogate, X: np.ndarray, expert,
                             thresholds=GOAL_THRESHOLDS) -> tuple[float, list[float]]:
    """The goal threshold under which ``surrogate`` shows the expert's mode on most of ``X``.

    Why: the expert gives its waypoint up once per aborted run, so beside a pending waypoint a
    +1 goal label is rare (0.14% of such states in the chapter 6 mission's expert runs) and a
    regression on +-1 learns an output that crosses 0 late; on that mission most of the
    surrogate's remaining errors were aborts the expert took and it did not.  Every threshold
    flies all of ``X`` in one batch (a threshold per vehicle).  Ties go to the middle of the
    best thresholds.  Returns (threshold, mode accuracy per threshold).
    """
    k = len(thresholds)
    rep = np.tile(np.asarray(X, float), (k, 1))
    scen = make_scenarios(mission, rep)
    if not scen.valid.all():
        raise ValueError("X: calibration needs valid scenarios (see sim.imitation.rollouts.draw_valid)")
    per_row = np.repeat(np.asarray(thresholds, float), len(X))
    scores, _ = run_scenarios(scen, None, False, None, driver=lambda sc: surrogate.autonomy(sc, per_row),
                              scan_beams=surrogate.spec.beams)
    modes = modes_from_scores(scores).reshape(k, len(X))
    ok = expert.valid & (modes >= 0)
    accuracy = [float(np.mean(modes[i][ok[i]] == expert.modes[ok[i]])) if ok[i].any() else 0.0 for i in range(k)]
    best = np.flatnonzero(np.isclose(accuracy, max(accuracy)))
    return float(thresholds[int(best[len(best) // 2])]), accuracy


def load_or_train(path: Path, mission: Mission, seed: int = 0, on_iteration=None, **options) -> tuple[Surrogate, bool]:
    """The surrogate saved at ``path`` (refused unless trained for ``mission``), or a new one saved there.

    Returns (surrogate, trained_now).
    """
    path = Path(path)
    if path.exists():
        return Surrogate.load(path, mission), False
    if path.suffix != ".npz":
        raise ValueError(f"--surrogate: a surrogate file ends in .npz, got {str(path)!r}")
    sur = train_surrogate(mission, seed=seed, on_iteration=on_iteration, **{**TRAINING_DEFAULTS, **options})
    sur.save(path)
    return sur, True


def mode_agreement(mission: Mission, surrogate: Surrogate, X: np.ndarray, expert=None) -> float:
    """Share of the valid scenarios ``X`` where the surrogate shows the expert's mode."""
    expert = sim.simulate(mission, X) if expert is None else expert
    mine = sim.simulate(mission, X, surrogate=surrogate)
    ok = expert.valid & mine.valid
    return float(np.mean(mine.modes[ok] == expert.modes[ok])) if ok.any() else float("nan")
