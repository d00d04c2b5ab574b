"""Imitation learning of a black-box policy: behavioural cloning, DAgger and Q-DAgger (section 6.4).

The learner never runs anything itself (like rapt's samplers): it is given a ``rollout``
callable that flies ``k`` runs with a policy in control — or the expert, when the policy
is None — and returns, per run, the features seen and the expert's action at every step
(the expert annotates states the learner's policy reached). Three ways to aggregate:

* ``supervised`` — behavioural cloning: the expert flies every run; all data kept.
* ``dagger`` — the learned policy flies; every annotated state is aggregated.
* ``qdagger`` — Algorithm 9: the learned policy flies; of each new set only the states it
  predicted worst (loss at or above the ``quantile``) are aggregated, which over-samples
  decisions (turns, aborts) and under-samples long straight legs, so each update trains
  on less data.

The policy is the multilayer perceptron of Table 6.1 (sigmoid hidden layers 150 and 50,
linear output, mean squared error, Adam), trained with scikit-learn and evaluated by
:class:`MLPPolicy` in plain numpy float32, so a decision inside a vectorised simulator is
three matrix products.  PolicyUpdate continues from the previous weights (warm start).
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.special import expit

__all__ = ["MLPPolicy", "Trajectory", "IterationRecord", "ImitationResult", "imitate", "METHODS", "HIDDEN"]

METHODS = ("supervised", "dagger", "qdagger")
#: Hidden layers of Table 6.1 (input is the feature vector, output the action).
HIDDEN = (150, 50)


@dataclass
class MLPPolicy:
    """A trained multilayer perceptron as float32 arrays: ``a = W3 s(W2 s(W1 f + b1) + b2) + b3``."""

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    activation: str = "logistic"

    @classmethod
    def from_sklearn(cls, model) -> "MLPPolicy":
        return cls([np.asarray(w, np.float32) for w in model.coefs_],
                   [np.asarray(b, np.float32) for b in model.intercepts_], model.activation)

    @property
    def n_features(self) -> int:
        return int(self.weights[0].shape[0])

    def __call__(self, F: np.ndarray, quiet: slice | None = None, quiet_value: float = 1.0) -> np.ndarray:
        """Actions for features ``F`` (n, features).

        ``quiet`` names a block of columns that mostly all read ``quiet_value`` (a range
        scan seeing nothing): rows where they do skip that block of the first product,
        which is most of the work when the block is most of the input.
        """
        h = np.asarray(F, dtype=np.float32)
        last = len(self.weights) - 1
        for k, (W, b) in enumerate(zip(self.weights, self.biases)):
            if k == 0 and quiet is not None:
                h = self._first_layer(h, quiet, quiet_value)
            else:
                h = h @ W + b
            if k < last:
                if self.activation == "logistic":
                    h = expit(h)
                elif self.activation == "relu":
                    np.maximum(h, 0, out=h)
                elif self.activation == "tanh":
                    np.tanh(h, out=h)
                else:
                    raise ValueError(f"activation: unknown {self.activation!r}")
        return h

    def _first_layer(self, F: np.ndarray, quiet: slice, value: float) -> np.ndarray:
        key = (quiet.start, quiet.stop, value)
        cache = self.__dict__.setdefault("_split", {})
        if key not in cache:
            W, b = self.weights[0], self.biases[0]
            cols = np.zeros(W.shape[0], dtype=bool)
            cols[quiet] = True
            Wq = np.ascontiguousarray(W[cols])
            cache[key] = (np.flatnonzero(~cols), np.ascontiguousarray(W[~cols]), Wq,
                          (b + value * Wq.sum(axis=0)).astype(np.float32))
        rest, W_rest, Wq, b_rest = cache[key]
        Fq = F[:, quiet]
        h = F[:, rest] @ W_rest + b_rest
        busy = np.flatnonzero(np.any(Fq != value, axis=1))
        if busy.size:
            h[busy] += (Fq[busy] - np.float32(value)) @ Wq
        return h

    def to_arrays(self) -> dict[str, np.ndarray]:
        out = {f"W{k}": w for k, w in enumerate(self.weights)}
        out.update({f"b{k}": b for k, b in enumerate(self.biases)})
        out["activation"] = np.array(self.activation)
        return out

    @classmethod
    def from_arrays(cls, arrays) -> "MLPPolicy":
        n = sum(1 for k in arrays if str(k).startswith("W"))
        return cls([np.asarray(arrays[f"W{k}"], np.float32) for k in range(n)],
                   [np.asarray(arrays[f"b{k}"], np.float32) for k in range(n)], str(arrays["activation"]))


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
    extra: dict = field(default_factory=dict)


@dataclass
class ImitationResult:
    policy: MLPPolicy
    method: str
    quantile: float | None
    history: list[IterationRecord]

    @property
    def runs(self) -> int:
        return self.history[-1].runs if self.history else 0


Rollout = Callable[[MLPPolicy | None, int, int], Sequence[Trajectory]]


def _stack(trajs: Sequence[Trajectory]) -> tuple[np.ndarray, np.ndarray]:
    trajs = [t for t in trajs if t.features.shape[0]]
    if not trajs:
        raise ValueError("rollout: returned no annotated states")
    return (np.concatenate([t.features for t in trajs]).astype(np.float32),
            np.concatenate([t.expert for t in trajs]).astype(np.float32))


def imitate(rollout: Rollout, *, method: str = "qdagger", quantile: float = 0.5, iterations: int = 15,
            runs_per_iteration: int = 5, initial_runs: int | None = None, hidden: Sequence[int] = HIDDEN,
            epochs: int = 20, learning_rate: float = 1e-3, batch_size: int = 256, seed: int = 0,
            on_iteration: Callable[[IterationRecord, MLPPolicy], None] | None = None) -> ImitationResult:
    """Train a policy imitating the expert behind ``rollout`` (see the module docstring).

    ``rollout(policy, k, iteration)`` flies ``k`` new runs (the expert flies when ``policy``
    is None) and returns their :class:`Trajectory`; it chooses the scenarios, seeded by
    the iteration.  Iteration 0 is the expert's ``initial_runs`` (default
    ``runs_per_iteration``); each of the ``iterations`` after it adds
    ``runs_per_iteration`` annotated runs.  ``on_iteration(record, policy)`` may evaluate
    the policy and put figures in ``record.extra``.
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    if method not in METHODS:
        raise ValueError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method == "qdagger" and not 0.0 <= quantile < 1.0:
        raise ValueError(f"quantile: expected a fraction in [0, 1), got {quantile!r}")
    for name, value in (("iterations", iterations), ("runs_per_iteration", runs_per_iteration), ("epochs", epochs)):
        if int(value) != value or value < (0 if name == "iterations" else 1):
            raise ValueError(f"{name}: expected a positive whole number, got {value!r}")
    model = MLPRegressor(hidden_layer_sizes=tuple(hidden), activation="logistic", solver="adam",
                         learning_rate_init=learning_rate, batch_size=batch_size, max_iter=epochs,
                         warm_start=True, shuffle=True, random_state=seed, tol=0.0, n_iter_no_change=10 ** 9)
    started = time.perf_counter()
    history: list[IterationRecord] = []
    policy: MLPPolicy | None = None
    F = A = None
    runs = 0
    for it in range(iterations + 1):
        t0 = time.perf_counter()
        k = (initial_runs or runs_per_iteration) if it == 0 else runs_per_iteration
        flier = None if (it == 0 or method == "supervised") else policy
        Fi, Ai = _stack(rollout(flier, k, it))
        runs += k
        t1 = time.perf_counter()
        if F is None:
            F, A = Fi, Ai
        elif method == "qdagger":
            loss = np.sum((policy(Fi) - Ai) ** 2, axis=1)
            keep = loss >= np.quantile(loss, quantile)
            F, A = np.concatenate([F, Fi[keep]]), np.concatenate([A, Ai[keep]])
        else:
            F, A = np.concatenate([F, Fi]), np.concatenate([A, Ai])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.set_params(batch_size=min(batch_size, F.shape[0]))
            model.fit(F, A if A.shape[1] > 1 else A[:, 0])
        policy = MLPPolicy.from_sklearn(model)
        t2 = time.perf_counter()
        mse = float(np.mean((policy(F) - A) ** 2))
        record = IterationRecord(it, runs, int(F.shape[0]), t1 - t0, t2 - t1, t2 - started, mse)
        if on_iteration is not None:
            on_iteration(record, policy)
        history.append(record)
    return ImitationResult(policy, method, quantile if method == "qdagger" else None, history)
