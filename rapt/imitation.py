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
:class:`MLPPolicy` in numpy on exact grids, so a decision inside a vectorised simulator is
three matrix products whose result for a row never depends on the batch around it.
PolicyUpdate continues from the previous weights (warm start).

``heads`` splits the action between networks of that shape, each reading only some
features (:class:`HeadsPolicy`): a decision the expert takes on a few features, learned
by the network that also steers on hundreds, picks up dependence on the rest that the
expert does not have.

``decisions`` names action columns that are discrete switches (+1 / -1: abort, return,
transmit).  Regressed on +-1 with squared error, a switch the expert throws once per run
(after which the run no longer shows the state) is a rare label, and the learned output
is a ramp whose zero crossing lies late or early by more than the boundary it should
place.  A decision column instead gets a network of its own trained as a classifier
(logistic output, cross-entropy, which keeps sharpening a separable switch where squared
error settles), its two classes weighed equally, and the states within ``switch_window``
steps of one of the expert's switches in their run weighed ``switch_weight`` times more:
those states fix where the switch lies.  Its output is ``2 p - 1`` (p the probability of
+1), on the scale of the labels.  Adam over a few epochs an update still leaves a ramp a
few percent of the input range wide (the expert's switch on charge is a fraction of a
watt-hour), so once the updates are done each decision is refitted by L-BFGS to
convergence on standardised inputs by a few small networks whose logits are averaged
(:data:`SHARP_HIDDEN`, :data:`SHARP_MEMBERS`), on the states where it is taken, all those
near a switch and a seeded ``far_share`` of the rest.
The updates themselves keep the smoother Adam classifier: trained to convergence on the
first updates' handful of switches, a network generalises them badly and the learner,
turning home early, never shows the late states that would correct it.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from rapt.errors import InputError

__all__ = [
    "MLPPolicy",
    "HeadsPolicy",
    "Policy",
    "policy_from_arrays",
    "Trajectory",
    "IterationRecord",
    "ImitationResult",
    "imitate",
    "METHODS",
    "HIDDEN",
]

#: Inputs and hidden activations are rounded to multiples of 2**-INPUT_BITS (see MLPPolicy.__call__).
INPUT_BITS = 16
_UNIT = 2.0**INPUT_BITS
#: exp's argument is capped here: 2^16 / (1 + e^40) already rounds to 0 units, and e^710 overflows.
_EXP_CAP = 40.0


def _units(F: np.ndarray) -> np.ndarray:
    """Inputs in whole units of 2**-INPUT_BITS, as a new float64 array."""
    k = np.array(F, dtype=np.float64)
    k *= _UNIT
    return np.rint(k, out=k)


def _grid(a: np.ndarray, bits: int) -> np.ndarray:
    """``a`` rounded to multiples of 2**-bits (exactly, in float64)."""
    return np.round(np.asarray(a, np.float64) * 2.0**bits) / 2.0**bits


METHODS = ("supervised", "dagger", "qdagger")
#: Hidden layers of Table 6.1 (input is the feature vector, output the action).
HIDDEN = (150, 50)


@dataclass
class MLPPolicy:
    """A trained multilayer perceptron as float32 arrays: ``a = W3 s(W2 s(W1 f + b1) + b2) + b3``."""

    weights: list[np.ndarray]
    biases: list[np.ndarray]
    activation: str = "logistic"
    #: "identity" (a regressor) or "decision" (a binary classifier's ``2 sigmoid(z) - 1``).
    output: str = "identity"

    @classmethod
    def from_sklearn(cls, model) -> MLPPolicy:
        """A copy of ``model``'s weights: a warm-started model trained on float32 keeps float32 weights
        and updates them in place, which would retrain every policy taken from it before."""
        return cls(
            [np.array(w, np.float32) for w in model.coefs_],
            [np.array(b, np.float32) for b in model.intercepts_],
            model.activation,
            "decision" if getattr(model, "out_activation_", "identity") == "logistic" else "identity",
        )

    @property
    def n_features(self) -> int:
        return int(self.weights[0].shape[0])

    @property
    def n_outputs(self) -> int:
        return int(self.weights[-1].shape[1])

    def __call__(self, F: np.ndarray, quiet: slice | None = None, quiet_value: float = 1.0) -> np.ndarray:
        """Actions for features ``F`` (n, features) in [-1, 1]; a row's action never depends on the other rows.

        BLAS sums a row in an order that depends on the batch around it, so float products
        differ in the last bits from batch to batch.  Here the inputs and every hidden
        activation are rounded to multiples of 2^-16 and each layer's weights to a power of
        two small enough that every partial sum is exact in float64: the products are then
        exact whatever the order, and a scenario flown alone (on the bus) decides bit for
        bit as inside any batch.  (The rounding is far below what the network resolves.)
        ``quiet`` names a block of columns that mostly all read ``quiet_value`` (a range
        scan seeing nothing): rows where they do skip that block of the first product, most
        of the work when the block is most of the input.

        The work arrays hold activations in units of 2^-16 (whole numbers) against weights
        scaled by 2^-16, and a logistic layer's weights are negated so that its product is
        already the exponent of ``1 / (1 + exp(-z))``: the same exact sums, with no pass
        spent rescaling or negating (this is the hot path of every learned decision).
        """
        (W, b), *deeper = self._exact()
        h = _units(F) @ W + b if quiet is None else self._first_layer(F, W, b, quiet, quiet_value)
        for W, b in deeper:
            self._activate(h)
            h = h @ W
            h += b
        if self.output == "decision":  # 2 sigmoid(z) - 1, elementwise: still independent of the batch
            h *= 0.5
            np.tanh(h, out=h)
        return h.astype(np.float32)

    def _activate(self, h: np.ndarray) -> None:
        """The hidden activation of ``h`` in place, in units of 2^-16 rounded to whole units."""
        if self.activation == "logistic":  # h holds -z (negated weights): 2^16 / (1 + exp(-z))
            np.minimum(h, _EXP_CAP, out=h)
            np.exp(h, out=h)
            h += 1.0
            np.divide(_UNIT, h, out=h)
        else:
            np.tanh(h, out=h)
            h *= _UNIT
        np.rint(h, out=h)

    def _exact(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Float64 layers with weights on the grid that keeps every partial sum exact, scaled by
        2^-16 to take activations in whole units, negated where a logistic follows (cached)."""
        cached = self.__dict__.get("_layers")
        if cached is None:
            if self.activation not in ("logistic", "tanh"):
                raise InputError(f"activation: expected 'logistic' or 'tanh' (bounded), got {self.activation!r}")
            if self.output not in ("identity", "decision"):
                raise InputError(f"output: expected 'identity' or 'decision', got {self.output!r}")
            cached = []
            last = len(self.weights) - 1
            for k, (W, b) in enumerate(zip(self.weights, self.biases)):
                W = np.asarray(W, np.float64)
                input_max = 2.0 if k == 0 else 1.0  # a quiet block enters as (x - value), |.| <= 2
                bound = float(np.abs(W).sum(axis=0).max() * input_max) + 1.0
                bits = int(min(24, np.floor(52 - INPUT_BITS - np.log2(bound))))
                sign = -1.0 if k < last and self.activation == "logistic" else 1.0
                cached.append((_grid(W, bits) * (sign / _UNIT), sign * np.asarray(b, np.float64)))
            self.__dict__["_layers"] = cached
        return cached

    def _first_layer(self, F: np.ndarray, W: np.ndarray, b: np.ndarray, quiet: slice, value: float) -> np.ndarray:
        """The first product, skipping the quiet block of rows where it reads ``value``: only the rest
        of the input is put on the grid.  (A row compared busy whose block rounds to ``value``
        anyway adds exact zeros, so the answer is the same.)"""
        key = (quiet.start, quiet.stop, value)
        cache = self.__dict__.setdefault("_split", {})
        if key not in cache:
            if value * _UNIT != np.rint(value * _UNIT):  # else a quiet row would differ from its grid value
                raise InputError(f"quiet_value: {value!r} is not a multiple of 2**-{INPUT_BITS}; use such a value")
            cols = np.zeros(W.shape[0], dtype=bool)
            cols[quiet] = True
            Wq = np.ascontiguousarray(W[cols])
            cache[key] = (
                np.flatnonzero(~cols),
                np.ascontiguousarray(W[~cols]),
                Wq,
                b + (value * _UNIT) * Wq.sum(axis=0),
            )
        rest, W_rest, Wq, b_rest = cache[key]
        h = _units(F[:, rest]) @ W_rest
        h += b_rest
        busy = np.flatnonzero(np.any(F[:, quiet] != value, axis=1))
        if busy.size:
            d = _units(F[busy, quiet])
            d -= value * _UNIT
            h[busy] += d @ Wq
        return h

    def to_arrays(self) -> dict[str, np.ndarray]:
        out = {f"W{k}": w for k, w in enumerate(self.weights)}
        out.update({f"b{k}": b for k, b in enumerate(self.biases)})
        out["activation"] = np.array(self.activation)
        out["output"] = np.array(self.output)
        return out

    @classmethod
    def from_arrays(cls, arrays) -> MLPPolicy:
        n = sum(1 for k in arrays if str(k).startswith("W"))
        return cls(
            [np.asarray(arrays[f"W{k}"], np.float32) for k in range(n)],
            [np.asarray(arrays[f"b{k}"], np.float32) for k in range(n)],
            str(arrays["activation"]),
            str(arrays["output"]) if "output" in arrays else "identity",
        )


@dataclass
class HeadsPolicy:
    """Networks that each read some feature columns and write some action columns (``heads``).

    Why: the expert may take part of its action on a few features (whether to abort on
    charge and distance) and the rest on many (steering on a range scan).  One network
    for both learns the first part with spurious weight on the other features, and a
    latched decision fires on the first spike; a head that never sees those features
    cannot.  Each head is an :class:`MLPPolicy`, so a row still never depends on its batch.
    """

    n_features: int
    heads: list[tuple[np.ndarray, np.ndarray, MLPPolicy]]  # (input columns, output columns, network)

    @property
    def n_outputs(self) -> int:
        return int(sum(outs.size for _, outs, _ in self.heads))

    def __call__(self, F: np.ndarray, quiet: slice | None = None, quiet_value: float = 1.0) -> np.ndarray:
        F = np.asarray(F)
        out = np.empty((F.shape[0], self.n_outputs), dtype=np.float32)
        for (cols, outs, net), (everything, local) in zip(self.heads, self._plan(quiet)):
            out[:, outs] = net(F if everything else F[:, cols], local, quiet_value)
        return out

    def _plan(self, quiet: slice | None) -> list[tuple[bool, slice | None]]:
        """Per head: whether it reads every column, and ``quiet`` in its own columns (cached: a hot path)."""
        key = None if quiet is None else (quiet.start, quiet.stop, quiet.step)
        cache = self.__dict__.setdefault("_plans", {})
        if key not in cache:
            cache[key] = [
                (_all_columns(cols, self.n_features), _local(cols, quiet, self.n_features)) for cols, _, _ in self.heads
            ]
        return cache[key]

    def to_arrays(self) -> dict[str, np.ndarray]:
        arrays: dict[str, np.ndarray] = {"n_features": np.array(self.n_features)}
        for j, (cols, outs, net) in enumerate(self.heads):
            arrays[f"h{j}_inputs"], arrays[f"h{j}_outputs"] = cols, outs
            arrays.update({f"h{j}_{k}": v for k, v in net.to_arrays().items()})
        return arrays

    @classmethod
    def from_arrays(cls, arrays) -> HeadsPolicy:
        heads, j = [], 0
        while f"h{j}_inputs" in arrays:
            own = {k[len(f"h{j}_") :]: v for k, v in arrays.items() if k.startswith(f"h{j}_")}
            heads.append(
                (
                    np.asarray(own.pop("inputs"), np.int64),
                    np.asarray(own.pop("outputs"), np.int64),
                    MLPPolicy.from_arrays(own),
                )
            )
            j += 1
        return cls(int(arrays["n_features"]), heads)


def _all_columns(cols: np.ndarray, n: int) -> bool:
    return cols.size == n and bool(np.all(cols == np.arange(n)))


def _local(cols: np.ndarray, quiet: slice | None, n_features: int) -> slice | None:
    """``quiet`` (columns of the full features) as columns of a head reading ``cols``, if all in one run."""
    if quiet is None:
        return None
    inside = np.flatnonzero((cols >= quiet.start) & (cols < quiet.stop))
    span = len(range(*quiet.indices(n_features)))
    if inside.size != span or (inside.size and inside[-1] - inside[0] + 1 != span):
        return None
    return slice(int(inside[0]), int(inside[-1]) + 1) if inside.size else None


#: What :func:`imitate` trains: one network, or one per head (``heads``).
Policy = MLPPolicy | HeadsPolicy


def policy_from_arrays(arrays) -> Policy:
    """The policy saved by ``to_arrays`` (one network, or heads)."""
    return HeadsPolicy.from_arrays(arrays) if "h0_inputs" in arrays else MLPPolicy.from_arrays(arrays)


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


def _near_switches(A: np.ndarray, lengths: list[int], decisions: Sequence[int], window: int) -> np.ndarray:
    """Whether each stacked state lies within ``window`` steps of a switch of a ``decisions`` column
    in its own run (``lengths``: the runs' numbers of states, in order)."""
    near = np.zeros(A.shape[0], dtype=bool)
    start = 0
    for n in lengths:
        for d in decisions:
            label = A[start : start + n, d] > 0
            for k in (np.flatnonzero(label[1:] != label[:-1]) + 1).tolist():
                near[start + max(k - window, 0) : start + min(k + window, n)] = True
        start += n
    return near


class _DecisionLearner:
    """One decision column's classifier across updates (see the module docstring)."""

    def __init__(self, options: dict, epochs: int, weight: float, seed: int):
        from sklearn.neural_network import MLPClassifier

        self.model = MLPClassifier(**options, random_state=seed)
        self.epochs, self.weight = epochs, weight

    def fit(self, x: np.ndarray, positive: np.ndarray, near: np.ndarray) -> MLPPolicy:
        """``epochs`` more passes over states ``x`` labelled ``positive``; the classifier as a policy."""
        w = np.where(near, self.weight, 1.0)
        if positive.any() and not positive.all():  # each class carries half the weight
            total = w.sum()
            for cls in (positive, ~positive):
                w[cls] *= total / (2.0 * w[cls].sum())
        self.model.set_params(batch_size=min(int(self.model.batch_size), x.shape[0]))
        for _ in range(self.epochs):  # one pass each; the classes are fixed up front, as the first
            # runs may show no switch at all
            self.model.partial_fit(x, positive.astype(np.int64), classes=[0, 1], sample_weight=w)
        return MLPPolicy.from_sklearn(self.model)


#: The classifier that sharpens a decision at the end: SHARP_MEMBERS networks of one small hidden
#: layer, each trained to convergence by L-BFGS from its own start, their logits averaged.  A
#: switch depends on a few features; a small network has little room to lean on the others, and
#: the average steadies where members trained on the same states place it.
SHARP_HIDDEN = 4
SHARP_MEMBERS = 5


def _sharp_classifier(
    x: np.ndarray, positive: np.ndarray, near: np.ndarray, iterations: int, far_share: float, seed: int
) -> MLPPolicy | None:
    """A classifier of ``positive`` on ``x`` trained by L-BFGS on standardised inputs, from the states
    ``near`` a switch and a seeded ``far_share`` of the rest; None without both classes.  The
    members' average logit is itself one network (their hidden units side by side)."""
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPClassifier

    rng = np.random.default_rng([seed, 0x736861])
    keep = near | (rng.random(near.size) < far_share)
    x, positive = x[keep], positive[keep]
    if positive.all() or not positive.any():
        return None
    mu, sd = x.mean(axis=0), np.maximum(x.std(axis=0), 1e-3)
    members = []
    for k in range(SHARP_MEMBERS):
        model = MLPClassifier(
            (SHARP_HIDDEN,),
            activation="logistic",
            solver="lbfgs",
            max_iter=iterations,
            tol=0.0,
            random_state=seed * SHARP_MEMBERS + k,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            model.fit((x - mu) / sd, positive.astype(np.int64))
        members.append(model)
    W0 = np.concatenate([m.coefs_[0] for m in members], axis=1) / sd[:, None]  # standardisation folded in
    b0 = np.concatenate([m.intercepts_[0] for m in members]) - mu @ W0
    W1 = np.concatenate([m.coefs_[1] for m in members], axis=0) / SHARP_MEMBERS
    b1 = np.mean([m.intercepts_[1] for m in members], axis=0)
    return MLPPolicy(
        [W0.astype(np.float32), W1.astype(np.float32)],
        [b0.astype(np.float32), b1.astype(np.float32)],
        "logistic",
        "decision",
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
    classifier in a head of its own (see the module docstring; without ``heads`` every
    decision gets a head reading all features).  After the last update each decision of
    the policy returned is sharpened (``sharpen_iterations`` L-BFGS iterations, 0: not),
    on the states where ``decided_where(F)`` says it is taken (default all).
    """
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.neural_network import MLPRegressor

    if method not in METHODS:
        raise InputError(f"method: expected one of {', '.join(METHODS)}, got {method!r}")
    if method == "qdagger" and not 0.0 <= quantile < 1.0:
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
        Ni = _near_switches(Ai, lengths, decisions, switch_window)
        runs += k
        t1 = time.perf_counter()
        if F is None:
            F, A, Nt = Fi, Ai, Ni
            models = [
                _DecisionLearner(options, epochs, switch_weight, seed + j)
                if _is_decision(outs, decisions)
                else MLPRegressor(**options, max_iter=epochs, warm_start=True, random_state=seed + j)
                for j, (_, outs) in enumerate(split)
            ]
        elif method == "qdagger":
            assert policy is not None and Nt is not None  # F holds data, so an update has made a policy
            loss = np.sum((policy(Fi) - Ai) ** 2, axis=1)
            keep = loss >= np.quantile(loss, quantile)
            F, A, Nt = np.concatenate([F, Fi[keep]]), np.concatenate([A, Ai[keep]]), np.concatenate([Nt, Ni[keep]])
        else:
            assert Nt is not None
            F, A, Nt = np.concatenate([F, Fi]), np.concatenate([A, Ai]), np.concatenate([Nt, Ni])
        assert split is not None and A is not None and Nt is not None
        c1 = time.process_time()
        nets = []
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            for (cols, outs), model in zip(split, models):
                x = F if _all_columns(cols, F.shape[1]) else F[:, cols]
                if isinstance(model, _DecisionLearner):
                    nets.append(model.fit(x, A[:, outs[0]] > 0, Nt))
                else:
                    model.set_params(batch_size=min(batch_size, F.shape[0]))
                    y = A[:, outs]
                    w = np.where(Nt, switch_weight, 1.0) if decisions else None
                    model.fit(x, y if y.shape[1] > 1 else y[:, 0], sample_weight=w)
                    nets.append(MLPPolicy.from_sklearn(model))
        if len(split) == 1 and _all_columns(split[0][0], F.shape[1]) and _all_columns(split[0][1], A.shape[1]):
            policy = nets[0]
        else:
            policy = HeadsPolicy(F.shape[1], [(cols, outs, net) for (cols, outs), net in zip(split, nets)])
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
        taken = np.ones(F.shape[0], dtype=bool) if decided_where is None else np.asarray(decided_where(F), bool)
        sharpened = list(policy.heads)
        for j, (cols, outs, net) in enumerate(policy.heads):
            if _is_decision(outs, decisions):
                x = F[taken][:, cols]
                sharp = _sharp_classifier(x, A[taken, outs[0]] > 0, Nt[taken], sharpen_iterations, far_share, seed + j)
                sharpened[j] = (cols, outs, sharp if sharp is not None else net)
        policy = HeadsPolicy(policy.n_features, sharpened)
    return ImitationResult(policy, method, quantile if method == "qdagger" else None, history, chosen)


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
