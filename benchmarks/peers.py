"""Peer samplers that ``benchmarks/search_quality.py`` sets beside rapt's own methods.

They are not part of rapt; they exist so that the benchmark compares S-NDV with other
people's answers to "where should the next batch of simulations go", not only with
space-filling designs.  Each peer takes a synthetic system (``rapt.testfunctions``), a
budget, a batch size and a seed, and returns the evaluated unit-cube samples ``X`` in
the order they were evaluated (the same thing ``rapt.search(...).X`` gives for bounds
``[(0, 1)] * dim``).  Evaluation of the system is part of the timed search for every
peer, as it is for ``rapt.search``.

* :func:`python_adaptive_search` - the ``adaptive`` package (python-adaptive):
  ``Learner2D`` in 2-D, ``LearnerND`` otherwise, driven batch-wise through its
  ask/tell interface on a scalar function (class label as a float for a categorical
  system, the value itself for a continuous one).  Its default loss functions are used.
  The learners are deterministic, so every seed gives the same samples.
* :func:`uncertainty_search` - pool-based active learning by classifier uncertainty:
  a random forest retrained on all samples after every batch scores random candidates
  by predictive entropy and the batch takes the most uncertain ones.
"""

from __future__ import annotations

import numpy as np

from rapt.samplers.space_filling import sobol_points
from rapt.testfunctions.registry import get_system

__all__ = ["adaptive_available", "python_adaptive_search", "uncertainty_search", "probe_learnernd", "COMBINE"]

#: How the uncertainty learner combines its per-output scores (see :func:`uncertainty_search`).
COMBINE = "normalised"


# ----------------------------------------------------------------------- python-adaptive
def adaptive_available() -> bool:
    """Whether the ``adaptive`` package imports."""
    try:
        import adaptive  # noqa: F401
    except Exception:
        return False
    return True


def _scalar(system, X: np.ndarray) -> np.ndarray:
    """The scalar python-adaptive learns: the one output of a single-output system."""
    Y = system(X)
    if Y.shape[1] != 1:
        raise ValueError(f"python-adaptive peer: {system.name} has {Y.shape[1]} outputs; the learners take a scalar")
    return Y[:, 0]


def python_adaptive_search(system, budget: int, batch_size: int = 100, seed: int = 0) -> np.ndarray:
    """Sample ``system`` with python-adaptive's ``Learner2D`` (2-D) or ``LearnerND`` (n-D).

    The learner is asked for ``batch_size`` points at a time (``learner.ask``), the batch
    is evaluated in one vectorised call and told back with ``learner.tell_many``.  The
    function handed to the learner is never called by it (we evaluate), so it is a stub.
    ``seed`` is accepted for a uniform signature; the learners have no randomness.
    Returns the evaluated points, shape ``(budget, dim)``.
    """
    import adaptive

    dim = system.dim
    bounds = [(0.0, 1.0)] * dim

    def stub(x):  # pragma: no cover - the learner never calls it in ask/tell mode
        raise RuntimeError("evaluated by the benchmark, not by the learner")

    learner = adaptive.Learner2D(stub, bounds=bounds) if dim == 2 else adaptive.LearnerND(stub, bounds=bounds)
    done: list[np.ndarray] = []
    n_done = 0
    while n_done < budget:
        n = min(batch_size, budget - n_done)
        points, _ = learner.ask(n)
        P = np.asarray([tuple(p) for p in points], dtype=float).reshape(-1, dim)
        if P.shape[0] == 0:  # the learner has nothing left to propose
            break
        values = _scalar(system, np.clip(P, 0.0, 1.0))
        learner.tell_many([tuple(p) for p in P], values.tolist())
        done.append(P)
        n_done += P.shape[0]
    return np.clip(np.vstack(done), 0.0, 1.0)


# ------------------------------------------------------------------- uncertainty sampling
def _entropy(proba: np.ndarray) -> np.ndarray:
    p = np.clip(proba, 1e-12, 1.0)
    return -(proba * np.log(p)).sum(axis=1)


def _output_uncertainty(
    X: np.ndarray, y: np.ndarray, kind: str, cand: np.ndarray, random_state: int, n_estimators: int
) -> np.ndarray | None:
    """Predictive uncertainty of one output at the candidates, or None when it is constant so far.

    Categorical: entropy (nats) of a ``RandomForestClassifier``'s class probabilities.
    Continuous: the standard deviation across the trees of a ``RandomForestRegressor``
    fitted to the output min-max scaled to [0, 1] (high where the trees disagree, i.e.
    around cliffs; discretising into quantile bins and using a classifier's entropy was
    tried and found clearly weaker on Custom2D, so it is not the one used).
    """
    from sklearn.ensemble import RandomForestClassifier, RandomForestRegressor

    if kind == "continuous":
        lo, hi = float(y.min()), float(y.max())
        if hi <= lo:
            return None
        forest = RandomForestRegressor(n_estimators=n_estimators, random_state=random_state, n_jobs=1)
        forest.fit(X, (y - lo) / (hi - lo))
        per_tree = np.stack([tree.predict(cand) for tree in forest.estimators_])
        return per_tree.std(axis=0)
    labels = y.astype(np.int64)
    if np.unique(labels).size < 2:
        return None  # one class seen so far: the forest is certain everywhere
    forest = RandomForestClassifier(n_estimators=n_estimators, random_state=random_state, n_jobs=1)
    forest.fit(X, labels)
    return _entropy(forest.predict_proba(cand))


def uncertainty_search(
    system,
    budget: int,
    batch_size: int = 100,
    seed: int = 0,
    *,
    candidates_per_point: int = 10,
    n_estimators: int = 50,
    combine: str = COMBINE,
) -> np.ndarray:
    """Active learning by random-forest predictive uncertainty.

    Batch 0 is scrambled Sobol (the same points rapt's adaptive samplers start with).
    Then, for every batch ``b``: per output, a forest (``n_estimators=50``,
    ``random_state=seed + b``, ``n_jobs=1``) is fitted on all samples so far (see
    :func:`_output_uncertainty`); ``candidates_per_point * batch_size`` uniform
    candidates (seeded by ``(seed, b)``) are scored by their uncertainty summed over
    outputs, and the ``batch_size`` highest-scoring candidates form the batch.  With
    ``combine="normalised"`` each output's uncertainty is divided by its maximum over the
    candidates before summing (every output gets an equal say, whatever its units); with
    ``"sum"`` the raw values are summed.  For a single-output system both rank alike.
    Returns the evaluated points in order, shape ``(budget, dim)``.
    """
    if combine not in ("sum", "normalised"):
        raise ValueError(f"combine: expected 'sum' or 'normalised', got {combine!r}")
    dim = system.dim
    kinds = tuple(system.output_types)
    n0 = min(batch_size, budget)
    X = sobol_points(dim, seed, 0, n0)
    Y = system(X)
    b = 1
    while X.shape[0] < budget:
        n = min(batch_size, budget - X.shape[0])
        rng = np.random.default_rng(np.random.SeedSequence([seed, b]))
        cand = rng.random((max(candidates_per_point * n, n), dim))
        score = np.zeros(cand.shape[0])
        for j, kind in enumerate(kinds):
            u = _output_uncertainty(X, Y[:, j], kind, cand, seed + b, n_estimators)
            if u is None:
                continue
            if combine == "normalised":
                top = float(u.max())
                u = u / top if top > 0 else u
            score += u
        pick = np.argsort(-score, kind="stable")[:n]
        Xb = cand[pick]
        X = np.vstack([X, Xb])
        Y = np.vstack([Y, system(Xb)])
        b += 1
    return X


# --------------------------------------------------------------- LearnerND scaling probe
def _learnernd_child(system_name: str, batch: int, max_points: int, queue) -> None:
    import time

    import adaptive

    system = get_system(system_name)
    learner = adaptive.LearnerND(lambda x: 0.0, bounds=[(0.0, 1.0)] * system.dim)
    start = time.perf_counter()
    n = 0
    while n < max_points:
        points, _ = learner.ask(batch)
        P = np.asarray([tuple(p) for p in points], dtype=float).reshape(-1, system.dim)
        if P.shape[0] == 0:
            break
        learner.tell_many([tuple(p) for p in P], _scalar(system, P).tolist())
        n += P.shape[0]
        queue.put((n, time.perf_counter() - start))


def probe_learnernd(system_name: str, seconds: float, batch: int = 20, max_points: int = 500) -> dict:
    """Run ``LearnerND`` on a registered system in a child process for at most ``seconds``.

    The learner is asked and told ``batch`` points at a time up to ``max_points``; the
    child reports after every batch and is terminated when the time is up.  Returns
    ``{"points": n reached, "at": seconds when reached, "finished": bool, "limit": seconds}``.
    """
    import multiprocessing as mp
    import queue as queue_mod
    import time

    ctx = mp.get_context("fork") if "fork" in mp.get_all_start_methods() else mp.get_context()
    q = ctx.Queue()
    proc = ctx.Process(target=_learnernd_child, args=(system_name, batch, max_points, q), daemon=True)
    start = time.perf_counter()
    proc.start()
    reached, at = 0, 0.0
    while True:
        left = seconds - (time.perf_counter() - start)
        if left <= 0:
            break
        try:
            reached, at = q.get(timeout=min(left, 1.0))
        except queue_mod.Empty:
            if not proc.is_alive():
                break
            continue
        if reached >= max_points:
            break
    finished = reached >= max_points
    if proc.is_alive():
        proc.terminate()
    proc.join(5)
    return {"points": int(reached), "at": float(at), "finished": finished, "limit": float(seconds)}
