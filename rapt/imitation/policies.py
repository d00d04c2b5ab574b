"""The policies imitation learning trains, evaluated exactly in numpy (section 6.4, Table 6.1).

The policy is the multilayer perceptron of Table 6.1 (sigmoid hidden layers 150 and 50,
linear output), trained with scikit-learn (:mod:`rapt.imitation.dagger`) and evaluated by
:class:`MLPPolicy` in numpy on exact grids, so a decision inside a vectorised simulator is
three matrix products whose result for a row never depends on the batch around it.

``heads`` splits the action between networks of that shape, each reading only some
features (:class:`HeadsPolicy`): a decision the expert takes on a few features, learned
by the network that also steers on hundreds, picks up dependence on the rest that the
expert does not have.  Both save to and load from flat arrays (``to_arrays``,
:func:`policy_from_arrays`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rapt.errors import InputError

__all__ = ["INPUT_BITS", "MLPPolicy", "HeadsPolicy", "Policy", "policy_from_arrays", "reads_all_columns"]

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
                (reads_all_columns(cols, self.n_features), _local(cols, quiet, self.n_features))
                for cols, _, _ in self.heads
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


def reads_all_columns(cols: np.ndarray, n: int) -> bool:
    """Whether a head reading ``cols`` reads all ``n`` features in order (it is then given them unsliced)."""
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


#: What :func:`rapt.imitation.dagger.imitate` trains: one network, or one per head (``heads``).
Policy = MLPPolicy | HeadsPolicy


def policy_from_arrays(arrays) -> Policy:
    """The policy saved by ``to_arrays`` (one network, or heads)."""
    return HeadsPolicy.from_arrays(arrays) if "h0_inputs" in arrays else MLPPolicy.from_arrays(arrays)
