"""Imitation learning of a black-box policy: behavioural cloning, DAgger and Q-DAgger (section 6.4).

The learner never runs anything itself (like rapt's samplers): it is given a ``rollout``
callable that flies ``k`` runs with a policy in control — or the expert, when the policy
is None — and returns, per run, the features seen and the expert's action at every step
(the expert annotates states the learner's policy reached). Three ways to aggregate:

* ``supervised`` — behavioural cloning: the expert flies every run; all data kept.
* ``dagger`` — the learned policy flies; every annotated state is aggregated.
* ``qdagger`` — Algorithm 9 as written: the learned policy flies; its new set is
  aggregated whole, and of the aggregate so far only the states the policy now predicts
  worst (loss at or above the ``quantile`` of the aggregate's) are kept: D = D_i U D_eps.
  Re-mining the whole aggregate over-samples decisions (turns, aborts) and under-samples
  long straight legs, and bounds the training set (about |D_i| / (1 - quantile)), so each
  update trains on less data.  (The algorithm's line reads L <= Q_eps; its text, "only
  retain the worst predictions", is what is meant and what this does.)
* ``qdagger-new`` — the variant RAPT used before: the aggregate is kept whole and only each
  new set is trimmed to its worst-predicted quantile.

Each update trains the networks of Table 6.1 (mean squared error, Adam) with scikit-learn
and hands them on as the exact numpy policies of :mod:`rapt.imitation.policies`;
PolicyUpdate continues from the previous weights (warm start).  Decision columns are
classifiers of their own (:mod:`rapt.imitation.decisions`).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rapt.errors import InputError
from rapt.imitation.decisions import DecisionLearner, near_switches, sharp_classifier
from rapt.imitation.policies import HeadsPolicy, MLPPolicy, Policy, reads_all_columns

__all__ = ["Trajectory", "IterationRecord", "ImitationResult", "Rollout", "imitate", "METHODS", "HIDDEN"]

METHODS = ("supervised", "dagger", "qdagger", "qdagger-new")
#: Hidden layers of Table 6.1 (input is the feature vector, output the action).
HIDDEN = (150, 50)


@dataclass
class Trajectory:
    """One run's annotated states: features (M, F) and the expert's actions there (M, A)."""

    features: np.ndarray
    expert: np.ndarray


@dataclass
class IterationRecord:
    iteration: int
    runs: int  # annotated runs so far (expert in the loop)
    samples: int  # size of the aggregated dataset
    rollout_s: float
    fit_s: float
    elapsed_s: float
    loss: float  # mean squared error of the updated policy on its training set
    fit_cpu_s: float = 0.0  # CPU seconds of the fit (all threads): the fair figure on a shared machine
    extra: dict = field(default_factory=dict)


@dataclass
class ImitationResult:
    policy: Policy
    method: str
    quantile: float | None
    history: list[IterationRecord]
    chosen: int = -1  # the iteration whose policy this is (the best on ``select``, else the last)
    aggregate: tuple[np.ndarray, np.ndarray] | None = None  # the last update's training set (features, actions)

    @property
    def runs(self) -> int:
        return self.history[-1].runs if self.history else 0


Rollout = Callable[[Policy | None, int, int], Sequence[Trajectory]]


def _stack(trajs: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Runs' states and actions stacked, and each run's number of states."""
    trajs = [t for t in trajs if t.features.shape[0]]
    if not trajs:
        raise InputError("rollout: returned no annotated states")
    return (
        np.concatenate([t.features for t in trajs]).astype(np.float32),
        np.concatenate([t.expert for t in trajs]).astype(np.float32),
        [int(t.features.shape[0]) for t in trajs],
    )


def imitate(
    rollout: Rollout,
    *,
    method: str = "qdagger",
    quantile: float = 0.5,
    iterations: int = 15,
    runs_per_iteration: int = 5,
    initial_runs: int | None = None,
    hidden: Sequence[int] = HIDDEN,
    epochs: int = 20,
    learning_rate: float = 3e-3,
    batch_size: int = 256,
    seed: int = 0,
    select: Callable[[Policy], float | tuple[float, ...]] | None = None,
    on_iteration: Callable[[IterationRecord, Policy], None] | None = None,
    heads: Sequence[tuple[Sequence[int] | None, Sequence[int]]] | None = None,
    decisions: Sequence[int] = (),
    switch_window: int = 5,
    switch_weight: float = 10.0,
    decided_where: Callable[[np.ndarray], np.ndarray] | None = None,
    sharpen_iterations: int = 500,
    far_share: float = 0.1,
) -> ImitationResult:
    """Train a policy imitating the expert behind ``rollout`` (see the module docstring).

    ``rollout(policy, k, iteration)`` flies ``k`` new runs (the expert flies when ``policy``
    is None) and returns their :class:`Trajectory`; it chooses the scenarios, seeded by
    the iteration.  Iteration 0 is the expert's ``initial_runs`` (default
    ``runs_per_iteration``); each of the ``iterations`` after it adds
    ``runs_per_iteration`` annotated runs.  ``on_iteration(record, policy)`` may evaluate
    the policy and put figures in ``record.extra``.

    ``select(policy)`` scores each update's policy on held-out expert runs (higher is
    better) and the best is returned, as DAgger itself prescribes (Ross et al. 2011,
    Algorithm 3.1: "return best pi_i on validation"): a closed-loop figure such as mode
    accuracy swings from update to update although the loss falls, and the last policy
    is not the best one; ties go to the later, better-fed policy.  A tuple is compared
    element by element (a tie-breaker after the figure that counts; the first is recorded).
    Without it the last policy is returned.

    ``heads`` — (input columns or None for all, output columns) pairs covering every
    action column once — trains one network per head on its own columns
    (:class:`HeadsPolicy`); by default one network maps all features to all actions.
    ``decisions`` — action columns labelled +1 / -1 that are switches, each trained as a
    classifier in a head of its own (see :mod:`rapt.imitation.decisions`; without ``heads`` every
    decision gets a head reading all features).  After the last update each decision of
    the policy returned is sharpened (``sharpen_iterations`` L-BFGS iterations, 0: not),
    on the states where ``decided_where(F)`` says it is taken (default all).
    """
    _check_options(
        method,
        quantile,
        iterations,
        runs_per_iteration,
        epochs,
        switch_window,
        sharpen_iterations,
        switch_weight,
        far_share,
    )
    decisions = [int(d) for d in decisions]
    options = dict(
        hidden_layer_sizes=tuple(hidden),
        activation="logistic",
        solver="adam",
        learning_rate_init=learning_rate,
        batch_size=batch_size,
        shuffle=True,
        tol=0.0,
        n_iter_no_change=10**9,
    )

    started = time.perf_counter()
    history: list[IterationRecord] = []
    policy: Policy | None = None  # None until the first update, which iteration 0 makes
    models: list = []
    split: list[tuple[np.ndarray, np.ndarray]] | None = None
    F = A = Nt = None
    runs = 0
    best: tuple[tuple[float, ...], int, Policy] | None = None
    for it in range(iterations + 1):
        t0 = time.perf_counter()
        k = (initial_runs or runs_per_iteration) if it == 0 else runs_per_iteration
        flier = None if (it == 0 or method == "supervised") else policy
        Fi, Ai, lengths = _stack(rollout(flier, k, it))
        if split is None:  # the first runs give the shapes; heads and decisions are checked against them
            split = _heads(heads, decisions, Fi.shape[1], Ai.shape[1])
        Ni = near_switches(Ai, lengths, decisions, switch_window)
        runs += k
        t1 = time.perf_counter()
        if F is None:
            F, A, Nt = Fi, Ai, Ni
            models = _learners(split, decisions, options, epochs, switch_weight, seed)
        elif method == "qdagger":
            assert policy is not None and A is not None and Nt is not None  # an update has made a policy
            keep = _worst(policy, F, A, quantile)  # re-mine the aggregate under the policy that flew
            F, A, Nt = np.concatenate([Fi, F[keep]]), np.concatenate([Ai, A[keep]]), np.concatenate([Ni, Nt[keep]])
        elif method == "qdagger-new":
            assert policy is not None and A is not None and Nt is not None
            keep = _worst(policy, Fi, Ai, quantile)
            F, A, Nt = np.concatenate([F, Fi[keep]]), np.concatenate([A, Ai[keep]]), np.concatenate([Nt, Ni[keep]])
        else:
            assert Nt is not None
            F, A, Nt = np.concatenate([F, Fi]), np.concatenate([A, Ai]), np.concatenate([Nt, Ni])
        assert split is not None and A is not None and Nt is not None
        c1 = time.process_time()
        policy = _update(split, models, F, A, Nt, batch_size, decisions, switch_weight)
        t2, c2 = time.perf_counter(), time.process_time()
        mse = float(np.mean((policy(F) - A) ** 2))
        record = IterationRecord(it, runs, int(F.shape[0]), t1 - t0, t2 - t1, t2 - started, mse, c2 - c1)
        if select is not None:
            got = select(policy)
            score = tuple(float(v) for v in got) if isinstance(got, tuple) else (float(got),)
            record.extra["selection"] = score[0]
            if best is None or score >= best[0]:
                best = (score, it, policy)
        if on_iteration is not None:
            on_iteration(record, policy)
        history.append(record)
    chosen, policy = (best[1], best[2]) if best is not None else (len(history) - 1, policy)
    assert policy is not None  # iterations >= 0 was checked, so the loop updated at least once
    if sharpen_iterations and isinstance(policy, HeadsPolicy) and F is not None and A is not None and Nt is not None:
        policy = _sharpen(policy, F, A, Nt, decisions, decided_where, sharpen_iterations, far_share, seed)
    aggregate = (F, A) if F is not None and A is not None else None
    return ImitationResult(
        policy, method, quantile if method.startswith("qdagger") else None, history, chosen, aggregate
    )


def _worst(policy: Policy, F: np.ndarray, A: np.ndarray, quantile: float) -> np.ndarray:
    """Rows of states ``F`` whose squared error against the expert's ``A`` is at or above its ``quantile``."""
    loss = np.sum((policy(F) - A) ** 2, axis=1)
    return loss >= np.quantile(loss, quantile)


def _check_options(
    method: str,
    quantile: float,
    iterations: int,
    runs_per_iteration: int,
    epochs: int,
    switch_window: int,
    sharpen_iterations: int,
    switch_weight: float,
    far_share: float,
) -> None:
    """:func:`imitate`'s options checked before any run is flown."""
    if method not in METHODS:
        raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method.startswith("qdagger") and not 0.0 <= quantile < 1.0:
        raise InputError(f"quantile: expected a fraction in [0, 1), got {quantile!r}")
    for name, value in (
        ("iterations", iterations),
        ("runs_per_iteration", runs_per_iteration),
        ("epochs", epochs),
        ("switch_window", switch_window),
        ("sharpen_iterations", sharpen_iterations),
    ):
        if int(value) != value or value < (0 if name in ("iterations", "switch_window", "sharpen_iterations") else 1):
            raise InputError(f"{name}: expected a positive whole number, got {value!r}")
    if not switch_weight >= 1.0:
        raise InputError(f"switch_weight: expected a weight >= 1, got {switch_weight!r}")
    if not 0.0 < far_share <= 1.0:
        raise InputError(f"far_share: expected a share in (0, 1], got {far_share!r}")


def _learners(
    split: list[tuple[np.ndarray, np.ndarray]],
    decisions: Sequence[int],
    options: dict,
    epochs: int,
    weight: float,
    seed: int,
) -> list:
    """Per head, the model its updates continue: a decision's classifier, else a warm-started regressor."""
    from sklearn.neural_network import MLPRegressor

    return [
        DecisionLearner(options, epochs, weight, seed + j)
        if _is_decision(outs, decisions)
        else MLPRegressor(**options, max_iter=epochs, warm_start=True, random_state=seed + j)
        for j, (_, outs) in enumerate(split)
    ]


def _update(
    split: list[tuple[np.ndarray, np.ndarray]],
    models: list,
    F: np.ndarray,
    A: np.ndarray,
    Nt: np.ndarray,
    batch_size: int,
    decisions: Sequence[int],
    switch_weight: float,
) -> Policy:
    """One PolicyUpdate: every head's model trained further on the aggregated states ``F``, actions ``A``
    (states near a switch, ``Nt``, weighed ``switch_weight``); the networks as one policy."""
    from sklearn.exceptions import ConvergenceWarning

    nets = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        for (cols, outs), model in zip(split, models):
            x = F if reads_all_columns(cols, F.shape[1]) else F[:, cols]
            if isinstance(model, DecisionLearner):
                nets.append(model.fit(x, A[:, outs[0]] > 0, Nt))
            else:
                model.set_params(batch_size=min(batch_size, F.shape[0]))
                y = A[:, outs]
                w = np.where(Nt, switch_weight, 1.0) if decisions else None
                model.fit(x, y if y.shape[1] > 1 else y[:, 0], sample_weight=w)
                nets.append(MLPPolicy.from_sklearn(model))
    if len(split) == 1 and reads_all_columns(split[0][0], F.shape[1]) and reads_all_columns(split[0][1], A.shape[1]):
        return nets[0]
    return HeadsPolicy(F.shape[1], [(cols, outs, net) for (cols, outs), net in zip(split, nets)])


def _sharpen(
    policy: HeadsPolicy,
    F: np.ndarray,
    A: np.ndarray,
    Nt: np.ndarray,
    decisions: Sequence[int],
    decided_where: Callable[[np.ndarray], np.ndarray] | None,
    iterations: int,
    far_share: float,
    seed: int,
) -> HeadsPolicy:
    """``policy`` with each decision head refitted by :func:`~rapt.imitation.decisions.sharp_classifier`
    on the states where ``decided_where`` says it is taken (a head it cannot refit is kept)."""
    taken = np.ones(F.shape[0], dtype=bool) if decided_where is None else np.asarray(decided_where(F), bool)
    sharpened = list(policy.heads)
    for j, (cols, outs, net) in enumerate(policy.heads):
        if _is_decision(outs, decisions):
            x = F[taken][:, cols]
            sharp = sharp_classifier(x, A[taken, outs[0]] > 0, Nt[taken], iterations, far_share, seed + j)
            sharpened[j] = (cols, outs, sharp if sharp is not None else net)
    return HeadsPolicy(policy.n_features, sharpened)


def _is_decision(outs: np.ndarray, decisions: Sequence[int]) -> bool:
    return outs.size == 1 and int(outs[0]) in decisions


def _heads(heads, decisions: Sequence[int], n_features: int, n_actions: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``heads`` as column arrays, checked: inputs within the features, outputs covering each action
    once, each decision alone in its head.  Without ``heads``: one network for the continuous
    actions and one per decision, all reading every feature."""
    if any(d < 0 or d >= n_actions for d in decisions) or len(set(decisions)) != len(decisions):
        raise InputError(f"decisions: expected distinct action columns 0..{n_actions - 1}, got {list(decisions)}")
    if heads is None:
        rest = [c for c in range(n_actions) if c not in decisions]
        heads = ([(None, rest)] if rest else []) + [(None, [d]) for d in decisions]
    out, seen = [], []
    for j, (inputs, outputs) in enumerate(heads):
        cols = np.arange(n_features) if inputs is None else np.asarray(inputs, np.int64)
        outs = np.asarray(outputs, np.int64)
        if cols.size == 0 or cols.min() < 0 or cols.max() >= n_features or np.unique(cols).size != cols.size:
            raise InputError(f"heads[{j}]: input columns must be distinct features 0..{n_features - 1}")
        if any(int(o) in decisions for o in outs) and not _is_decision(outs, decisions):
            raise InputError(f"heads[{j}]: a decision column needs a head of its own, got outputs {outs.tolist()}")
        out.append((cols, outs))
        seen.extend(outs.tolist())
    if sorted(seen) != list(range(n_actions)):
        raise InputError(f"heads: output columns must cover the {n_actions} action columns once each, got {seen}")
    return out
