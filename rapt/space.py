"""State spaces: the scenario parameters a study varies, mapped to and from the unit cube.

Every sampler in :mod:`rapt.samplers` works in the unit cube ``[0, 1]^d`` so that its
distance-based information metrics do not depend on units (section 3.3.1 of the
dissertation normalises states to ``X̄``).  A :class:`StateSpace` owns the translation
between that cube and the physical scenario: continuous ranges, integer counts,
categorical choices and permutations (the mission-area priority order is one).

A permutation of ``n`` items uses ``n`` cube coordinates as *random keys*: the order of
the keys is the permutation.  That keeps every coordinate continuous, so nearest-neighbour
metrics see "nearly the same order" as "nearby".
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Any

import numpy as np
import numpy.typing as npt

from rapt.errors import InputError

__all__ = [
    "Continuous",
    "Integer",
    "Categorical",
    "Permutation",
    "StateSpace",
    "parameter_from_mapping",
]


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not name:
        raise InputError(f"parameter name must be a non-empty string, got {name!r}")
    return name


@dataclass(frozen=True)
class Continuous:
    """A real-valued parameter on ``[low, high]`` (optionally sampled on a log scale).

    ``resolution`` is the finest step the parameter can be set to in the world it describes (a
    surveyed position to 0.1 m, a clock to 1 s). A search moves continuously; a scenario that
    leaves it for the world is moved onto the steps by :meth:`snap_unit` (so it can be set up as
    simulated, and a last-digit difference in its cube coordinate does not reach it), and a value
    on a step up to rounding decodes as that step exactly (364.1, not 364.09999999999997).
    """

    name: str
    low: float
    high: float
    log: bool = False
    resolution: float | None = None
    kind: str = field(default="continuous", init=False)

    def __post_init__(self) -> None:
        _check_name(self.name)
        low, high = float(self.low), float(self.high)
        if not (math.isfinite(low) and math.isfinite(high)):
            raise InputError(f"parameter '{self.name}': bounds must be finite, got low={self.low}, high={self.high}")
        if low >= high:
            raise InputError(
                f"parameter '{self.name}': low must be < high, got low={low}, high={high}; swap or widen the bounds"
            )
        if self.log and low <= 0:
            raise InputError(f"parameter '{self.name}': log scale needs low > 0, got low={low}")
        if self.resolution is not None:
            step = self.resolution
            if isinstance(step, bool) or not isinstance(step, (int, float)) or not (0 < step <= (high - low) / 2):
                raise InputError(
                    f"parameter '{self.name}': resolution must be a number in (0, {(high - low) / 2:g}] "
                    f"(at least three settable values), got {step!r}; give the finest step the value can be set to"
                )

    @property
    def width(self) -> int:
        return 1

    def to_unit(self, values: npt.ArrayLike) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        if self.log:
            return (np.log(v) - math.log(self.low)) / (math.log(self.high) - math.log(self.low))
        return (v - self.low) / (self.high - self.low)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        if self.log:
            v = np.exp(math.log(self.low) + u * (math.log(self.high) - math.log(self.low)))
        else:
            v = self.low + u * (self.high - self.low)
        if self.resolution is None:
            return v
        k = v / self.resolution
        on_step = np.abs(k - np.round(k)) <= ON_STEP  # on a step up to the cube's rounding
        return np.where(on_step, np.clip(_steps(np.round(k), self.resolution), self.low, self.high), v)

    def snap_unit(self, u: npt.ArrayLike, away_from: npt.ArrayLike | None = None) -> np.ndarray:
        """Cube coordinates ``u`` moved so their values lie on the parameter's steps (unchanged without a
        resolution): to the nearest step, or, given ``away_from`` (a partner's coordinates), to the
        step on the far side from the partner, so a boundary pair's sides stay on their sides of it."""
        cube = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        if self.resolution is None:
            return cube
        k = self.from_unit(cube) / self.resolution
        if away_from is None:
            k = np.round(k)
        else:
            side = np.sign(k - self.from_unit(np.asarray(away_from, dtype=float)) / self.resolution)
            k = np.where(side > 0, np.ceil(k - ON_STEP), np.where(side < 0, np.floor(k + ON_STEP), np.round(k)))
        return self.to_unit(np.clip(_steps(k, self.resolution), self.low, self.high))


#: How far from a step (in steps) a decoded value may lie and still be that step: the cube's rounding.
ON_STEP = 1e-6


def _steps(k: np.ndarray, step: float) -> np.ndarray:
    """``k`` steps of ``step``, written as short as ``step`` is."""
    exponent = Decimal(repr(float(step))).normalize().as_tuple().exponent
    decimals = max(0, -exponent) if isinstance(exponent, int) else 0
    return np.round(k * step, decimals)


@dataclass(frozen=True)
class Integer:
    """An integer parameter on ``[low, high]`` inclusive; each value owns an equal slice of the cube."""

    name: str
    low: int
    high: int
    kind: str = field(default="integer", init=False)

    def __post_init__(self) -> None:
        _check_name(self.name)
        if int(self.low) != self.low or int(self.high) != self.high:
            raise InputError(
                f"parameter '{self.name}': integer bounds must be whole numbers, got {self.low}, {self.high}"
            )
        if self.low >= self.high:
            raise InputError(
                f"parameter '{self.name}': low must be < high, got low={self.low}, high={self.high}; swap or widen the bounds"
            )

    @property
    def width(self) -> int:
        return 1

    def to_unit(self, values: npt.ArrayLike) -> np.ndarray:
        v = np.asarray(values, dtype=float)
        n = self.high - self.low + 1
        return (v - self.low + 0.5) / n

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        n = self.high - self.low + 1
        idx = np.minimum(np.floor(np.clip(np.asarray(u, dtype=float), 0.0, 1.0) * n), n - 1)
        return (self.low + idx).astype(np.int64)


@dataclass(frozen=True)
class Categorical:
    """One choice among ``choices``; each choice owns an equal slice of the cube."""

    name: str
    choices: tuple
    kind: str = field(default="categorical", init=False)

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "choices", tuple(self.choices))
        if len(self.choices) < 2:
            raise InputError(f"parameter '{self.name}': a categorical parameter needs at least 2 choices")
        if len(set(map(repr, self.choices))) != len(self.choices):
            raise InputError(f"parameter '{self.name}': categorical choices must be distinct")

    @property
    def width(self) -> int:
        return 1

    def to_unit(self, values: Iterable[Any]) -> np.ndarray:
        index = {c: i for i, c in enumerate(self.choices)}
        try:
            idx = np.array([index[v] for v in values], dtype=float)
        except KeyError as exc:
            raise InputError(f"parameter '{self.name}': {exc.args[0]!r} is not one of {list(self.choices)}") from None
        return (idx + 0.5) / len(self.choices)

    def from_unit(self, u: np.ndarray) -> np.ndarray:
        n = len(self.choices)
        idx = np.minimum(np.floor(np.clip(np.asarray(u, dtype=float), 0.0, 1.0) * n), n - 1).astype(np.int64)
        out = np.empty(idx.shape, dtype=object)
        for i, c in enumerate(self.choices):
            out[idx == i] = c
        return out


@dataclass(frozen=True)
class Permutation:
    """An ordering of ``items`` encoded as one random key per item (argsort of the keys)."""

    name: str
    items: tuple
    kind: str = field(default="permutation", init=False)

    def __post_init__(self) -> None:
        _check_name(self.name)
        object.__setattr__(self, "items", tuple(self.items))
        if len(self.items) < 2:
            raise InputError(f"parameter '{self.name}': a permutation needs at least 2 items")
        if len(set(map(repr, self.items))) != len(self.items):
            raise InputError(f"parameter '{self.name}': permutation items must be distinct")

    @property
    def width(self) -> int:
        return len(self.items)

    def to_unit(self, orders: Iterable[Sequence[Any]]) -> np.ndarray:
        """Keys for each order: the item ranked r gets key (r + 0.5) / n."""
        n = len(self.items)
        index = {c: i for i, c in enumerate(self.items)}
        rows = []
        for order in orders:
            order = list(order)
            if sorted(map(repr, order)) != sorted(map(repr, self.items)) or len(order) != n:
                raise InputError(f"parameter '{self.name}': {order!r} is not an ordering of {list(self.items)}")
            keys = np.empty(n)
            for rank, item in enumerate(order):
                keys[index[item]] = (rank + 0.5) / n
            rows.append(keys)
        return np.array(rows).reshape(-1, n)

    def from_unit(self, u: np.ndarray) -> list[tuple]:
        u = np.asarray(u, dtype=float).reshape(-1, len(self.items))
        ranks = np.argsort(u, axis=1, kind="stable")
        return [tuple(self.items[i] for i in row) for row in ranks]


Parameter = Continuous | Integer | Categorical | Permutation

_KINDS = {
    "continuous": Continuous,
    "float": Continuous,
    "integer": Integer,
    "int": Integer,
    "categorical": Categorical,
    "permutation": Permutation,
}


def parameter_from_mapping(spec: Mapping[str, Any]) -> Parameter:
    """Build a parameter from a plain mapping such as ``{"name": "t0", "type": "continuous", "low": 0, "high": 12}``."""
    spec = dict(spec)
    kind = spec.pop("type", "continuous")
    if kind not in _KINDS:
        raise InputError(
            f"parameter '{spec.get('name', '?')}': unknown type {kind!r}; allowed: continuous, integer, categorical, permutation"
        )
    try:
        return _KINDS[kind](**spec)
    except TypeError as exc:
        raise InputError(f"parameter '{spec.get('name', '?')}' ({kind}): {exc}") from None


class StateSpace:
    """An ordered collection of parameters and the map between the unit cube and scenarios.

    ``dim`` is the number of cube coordinates (a permutation of n items takes n).
    """

    def __init__(self, parameters: Sequence[Parameter | Mapping[str, Any]]):
        params = [p if not isinstance(p, Mapping) else parameter_from_mapping(p) for p in parameters]
        if not params:
            raise InputError("parameters: a state space needs at least one parameter")
        for p in params:
            if not isinstance(p, (Continuous, Integer, Categorical, Permutation)):
                raise InputError(
                    f"parameters: {p!r} is not a parameter; use Continuous, Integer, Categorical or Permutation"
                )
        names = [p.name for p in params]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise InputError(f"parameters: duplicate names {dupes}; every parameter needs its own name")
        self.parameters: tuple[Parameter, ...] = tuple(params)
        self._slices: dict[str, slice] = {}
        start = 0
        for p in params:
            self._slices[p.name] = slice(start, start + p.width)
            start += p.width
        self.dim = start

    @classmethod
    def from_bounds(cls, bounds: Any) -> StateSpace:
        """A space of continuous parameters ``x0, x1, ...`` from ``[(low, high), ...]`` or a (d, 2) array."""
        if isinstance(bounds, StateSpace):
            return bounds
        arr = np.asarray(bounds, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] == 0:
            raise InputError(f"bounds: expected a sequence of (low, high) pairs, got shape {arr.shape}")
        bad = np.flatnonzero(~(arr[:, 0] < arr[:, 1]))
        if bad.size:
            i = int(bad[0])
            raise InputError(
                f"bounds: dimension {i} has low={arr[i, 0]} >= high={arr[i, 1]}; every low must be < its high"
            )
        if not np.all(np.isfinite(arr)):
            raise InputError("bounds: every low and high must be finite")
        return cls([Continuous(f"x{i}", lo, hi) for i, (lo, hi) in enumerate(arr)])

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    def slice_of(self, name: str) -> slice:
        return self._slices[name]

    @property
    def is_box(self) -> bool:
        """True when every parameter is continuous and linear (physical = affine map of the cube)."""
        return all(isinstance(p, Continuous) and not p.log for p in self.parameters)

    def bounds_array(self) -> np.ndarray:
        linear = [p for p in self.parameters if isinstance(p, Continuous) and not p.log]  # as is_box
        if len(linear) != len(self.parameters):
            raise InputError("bounds_array: only defined for spaces of linear continuous parameters")
        return np.array([[p.low, p.high] for p in linear], dtype=float)

    def from_unit_array(self, U: np.ndarray) -> np.ndarray:
        """Affine map of cube points to a float array (box spaces only) — the fast path for vectorised systems."""
        b = self.bounds_array()
        U = self._check_unit(U)
        return b[:, 0] + U * (b[:, 1] - b[:, 0])

    def to_unit_array(self, X: np.ndarray) -> np.ndarray:
        b = self.bounds_array()
        X = np.asarray(X, dtype=float)
        return (X - b[:, 0]) / (b[:, 1] - b[:, 0])

    def _check_unit(self, U: np.ndarray) -> np.ndarray:
        U = np.asarray(U, dtype=float)
        if U.ndim != 2 or U.shape[1] != self.dim:
            raise InputError(f"U: expected shape (n, {self.dim}), got {U.shape}")
        return U

    def decode(self, U: np.ndarray) -> list[dict[str, Any]]:
        """Unit-cube rows -> scenarios as ``{name: value}`` dicts (physical units, permutations as tuples)."""
        U = self._check_unit(U)
        columns = {}
        for p in self.parameters:
            col = U[:, self._slices[p.name]]
            columns[p.name] = p.from_unit(col if p.width > 1 else col[:, 0])
        out = []
        for i in range(U.shape[0]):
            row = {}
            for p in self.parameters:
                v = columns[p.name][i]
                row[p.name] = v.item() if isinstance(v, np.generic) else v
            out.append(row)
        return out

    def snap(self, U: np.ndarray, away_from: np.ndarray | None = None) -> np.ndarray:
        """Cube rows moved onto their parameters' resolutions (:meth:`Continuous.snap_unit`; other
        coordinates unchanged): what a scenario leaving the search for the world becomes.
        ``away_from``: per row, a partner to snap away from (a boundary pair's other side)."""
        U = self._check_unit(U).copy()
        partner = None if away_from is None else self._check_unit(away_from)
        for p in self.parameters:
            if isinstance(p, Continuous) and p.resolution is not None:
                c = self._slices[p.name].start
                U[:, c] = p.snap_unit(U[:, c], None if partner is None else partner[:, c])
        return U

    def encode(self, scenarios: Sequence[Mapping[str, Any]]) -> np.ndarray:
        """Scenarios as ``{name: value}`` -> unit-cube rows (inverse of :meth:`decode` up to slice centres)."""
        n = len(scenarios)
        U = np.empty((n, self.dim))
        for p in self.parameters:
            try:
                values = [s[p.name] for s in scenarios]
            except KeyError:
                raise InputError(f"scenarios: missing parameter '{p.name}'") from None
            u = p.to_unit(values)
            U[:, self._slices[p.name]] = np.asarray(u, dtype=float).reshape(n, p.width)
        if np.any((U < 0) | (U > 1)):
            bad = [
                p.name
                for p in self.parameters
                if np.any((U[:, self._slices[p.name]] < 0) | (U[:, self._slices[p.name]] > 1))
            ]
            raise InputError(f"scenarios: values outside the declared range for {bad}")
        return U

    def to_config(self) -> list[dict[str, Any]]:
        """A JSON-friendly description, stored with a study so a resumed run can check it."""
        out = []
        for p in self.parameters:
            d: dict[str, Any] = {"name": p.name, "type": p.kind}
            if isinstance(p, Continuous):
                d.update(low=float(p.low), high=float(p.high), log=bool(p.log))
                if p.resolution is not None:
                    d["resolution"] = float(p.resolution)
            elif isinstance(p, Integer):
                d.update(low=int(p.low), high=int(p.high))
            elif isinstance(p, Categorical):
                d["choices"] = list(p.choices)
            else:
                d["items"] = list(p.items)
            out.append(d)
        return out

    def __repr__(self) -> str:
        return f"StateSpace({', '.join(f'{p.name}:{p.kind}' for p in self.parameters)}; dim={self.dim})"

    def __eq__(self, other: object) -> bool:
        return isinstance(other, StateSpace) and self.to_config() == other.to_config()
