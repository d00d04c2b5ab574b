"""The ask/tell contract of :class:`rapt.samplers.base.Sampler`, held against every sampler.

python-adaptive style: one suite, parametrized over every sampler (the registered methods,
a Latin hypercube of fixed size, and the manifold sampler with single states and with whole
hulls), checking what the base class's docstring promises, no more:

* ``ask(n)``: (m, dim) unit-cube points with m <= n (exactly n for the registered
  methods), one batch counted per ask that returns points;
* finishing early: no points means :attr:`done`, for good;
* the same seed gives the same points, another seed other points;
* ``tell``: proposes nothing; rows told in pieces are rows told at once; the order of rows
  does not matter; telling rows again keeps asks valid, and changes nothing for a sampler
  that is not adaptive; only an adaptive sampler's asks depend on the scores;
* resuming (tell the rows, fast-forward the counters) asks what the original would.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pytest

import rapt
from rapt.manifold import ManifoldSampler
from rapt.samplers import METHODS, InformationSampler, Sampler, make_sampler
from tests.support.systems import disk

BOUNDS = [[0.0, np.pi], [0.0, np.pi]]
FACES = np.array([[0.25], [0.75]])


def projected(Q):
    """Two faces (phi 0.25 and 0.75); a query is snapped to the nearer; stable on the upper face or t < 0.5."""
    X = np.array(Q, dtype=float)
    X[:, 1] = np.where(Q[:, 1] < 0.5, 0.25, 0.75)
    y = ((X[:, 1] > 0.5) | (X[:, 0] < 0.5)).astype(float)
    return X, y, [FACES] * len(X)


def whole_hulls(Q):
    """As :func:`projected`, but every face of each asked t is labelled, with face identities 1 and 2."""
    t = np.unique(Q[:, 0])
    X = np.column_stack([np.repeat(t, 2), np.tile(FACES[:, 0], len(t))])
    y = ((X[:, 1] > 0.5) | (X[:, 0] < 0.5)).astype(float)
    ids = np.where(X[:, 1] > 0.5, 2, 1)
    return X, y, [FACES] * len(X), ids, [np.array([1, 2])] * len(X)


@dataclass(frozen=True)
class Case:
    """A sampler under the contract: how to build it and how its system answers a batch (``tell``'s arguments)."""

    name: str
    make: Callable[[int], Sampler]  # seed -> sampler
    evaluate: Callable[[np.ndarray], tuple]  # unit-cube queries -> tell(*args)
    exact: bool  # asks return exactly n

    def __repr__(self) -> str:
        return self.name


def _method(name: str, **options) -> Callable[[int], Sampler]:
    return lambda seed: make_sampler(name, 2, seed=seed, **options)


def _disk(Q):
    return Q, disk(Q)


CASES = [
    *(Case(name, _method(name), _disk, True) for name in METHODS),
    Case("lhs-size", _method("lhs", size=200), _disk, True),
    Case("manifold", lambda seed: ManifoldSampler(1, BOUNDS, seed=seed, n_initial=10), projected, False),
    Case(
        "manifold-hulls",
        lambda seed: ManifoldSampler(1, BOUNDS, seed=seed, n_initial=10, whole_hulls=True),
        whole_hulls,
        False,
    ),
]
ABSTRACT = {InformationSampler}  # shared machinery: no metamodel of its own


def rows(args: tuple, index) -> tuple:
    """``tell``'s arguments restricted to (and ordered as) the rows ``index``."""
    return tuple(a[index] if isinstance(a, np.ndarray) else [a[i] for i in index] for a in args)


def joined(*parts: tuple) -> tuple:
    """The ``tell`` arguments of several batches as one."""
    return tuple(
        np.concatenate(a) if isinstance(a[0], np.ndarray) else [x for part in a for x in part] for a in zip(*parts)
    )


def told(case: Case, seed: int = 0, n: int = 40) -> tuple:
    """``tell`` arguments for ``n`` random queries: enough rows for every sampler's adaptive phase."""
    return case.evaluate(np.random.default_rng(100 + seed).random((n, 2)))


def reference(case: Case) -> tuple[tuple, int, Sampler]:
    """:func:`told`'s rows, their number, and a fresh sampler (seed 1) told them at once, for comparisons."""
    data = told(case)
    s = case.make(1)
    s.tell(*data)
    return data, len(data[0]), s


def drive(case: Case, seed: int, sizes=(12, 12, 12, 12)) -> tuple[Sampler, list[np.ndarray], list[tuple]]:
    """Ask and tell batches of ``sizes``: the sampler, its asks and what it was told."""
    s = case.make(seed)
    asks, tells = [], []
    for n in sizes:
        Q = s.ask(n)
        asks.append(Q)
        tells.append(case.evaluate(Q))
        s.tell(*tells[-1])
    return s, asks, tells


def assert_valid_ask(s: Sampler, Q: np.ndarray, n: int, exact: bool) -> None:
    assert isinstance(Q, np.ndarray) and Q.dtype == np.float64
    assert Q.ndim == 2 and Q.shape[1] == s.dim
    assert (len(Q) == n) if exact else (1 <= len(Q) <= n)
    assert np.all(np.isfinite(Q)) and np.all((Q >= 0) & (Q <= 1))


def all_subclasses(cls: type) -> set[type]:
    out = set()
    for sub in cls.__subclasses__():
        out |= {sub} | all_subclasses(sub)
    return out


# --------------------------------------------------------------------------- coverage
def test_every_sampler_in_rapt_is_held_to_the_contract():
    for module in pkgutil.walk_packages(rapt.__path__, "rapt."):  # a sampler anywhere in rapt is found
        importlib.import_module(module.name)
    samplers = {cls for cls in all_subclasses(Sampler) if cls.__module__.startswith("rapt.")} - ABSTRACT
    assert samplers == {type(case.make(0)) for case in CASES}


# --------------------------------------------------------------------------- ask
@pytest.mark.parametrize("case", CASES, ids=repr)
def test_asks_are_unit_cube_points_of_the_asked_shape_one_batch_each(case):
    s = case.make(0)
    assert (s.n_batches, s.n_asked, s.done) == (0, 0, False)
    for n in (1, 5, 16, 16, 16, 3):  # through the initial batches into the adaptive phase
        batches, asked, told_before = s.n_batches, s.n_asked, s.n_told
        Q = s.ask(n)
        assert_valid_ask(s, Q, n, case.exact)
        assert (s.n_batches, s.n_asked, s.done) == (batches + 1, asked + len(Q), False)
        assert s.n_told == told_before  # asking tells nothing
        s.tell(*case.evaluate(Q))
        assert (s.n_batches, s.n_asked) == (batches + 1, asked + len(Q))  # telling asks nothing
    assert s.n_told >= 50


@pytest.mark.parametrize("case", CASES, ids=repr)
@pytest.mark.parametrize("bad", [0, -1, 2.5, "3", None])
def test_a_bad_batch_size_is_refused_and_counts_nothing(case, bad):
    s = case.make(0)
    with pytest.raises(ValueError, match="n: expected a positive integer"):
        s.ask(bad)
    assert (s.n_batches, s.n_asked, s.done) == (0, 0, False)


# --------------------------------------------------------------------------- seeds
@pytest.mark.parametrize("case", CASES, ids=repr)
def test_same_seed_same_points(case):
    a, asks_a, _ = drive(case, seed=4)
    b, asks_b, _ = drive(case, seed=4)
    assert all(np.array_equal(p, q) for p, q in zip(asks_a, asks_b, strict=True))
    assert np.array_equal(a.X, b.X) and np.array_equal(a.Y, b.Y)
    assert np.array_equal(a.ask(10), b.ask(10))


@pytest.mark.parametrize("case", CASES, ids=repr)
def test_other_seed_other_points(case):
    _, asks_a, _ = drive(case, seed=4)
    _, asks_b, _ = drive(case, seed=5)
    for p, q in zip(asks_a, asks_b):  # every batch, the initial ones and the adaptive ones
        assert p.shape != q.shape or not np.allclose(p, q)


# --------------------------------------------------------------------------- tell
@pytest.mark.parametrize("case", CASES, ids=repr)
def test_rows_told_in_pieces_are_rows_told_at_once(case):
    data, n, whole = reference(case)
    pieces = case.make(1)
    for index in np.array_split(np.arange(n), [7, 8, 25]):  # pieces of 7, 1, 17 and the rest
        pieces.tell(*rows(data, index))
    assert np.array_equal(whole.X, pieces.X) and np.array_equal(whole.Y, pieces.Y)
    assert (pieces.n_batches, pieces.n_asked, pieces.n_told) == (0, 0, n)
    assert np.array_equal(whole.ask(10), pieces.ask(10))


@pytest.mark.parametrize("case", CASES, ids=repr)
def test_the_order_of_the_rows_told_does_not_matter(case):
    data, n, straight = reference(case)
    shuffled = case.make(1)
    shuffled.tell(*rows(data, np.random.default_rng(7).permutation(n)))
    assert np.array_equal(straight.ask(10), shuffled.ask(10))
    later = case.evaluate(np.random.default_rng(8).random((10, 2)))
    straight.tell(*later)
    shuffled.tell(*rows(later, np.arange(len(later[0]))[::-1]))
    assert np.array_equal(straight.ask(10), shuffled.ask(10))


@pytest.mark.parametrize("case", CASES, ids=repr)
def test_only_an_adaptive_sampler_asks_depend_on_the_scores(case):
    data, n, a = reference(case)
    shuffled = list(data)
    shuffled[1] = data[1][np.random.default_rng(9).permutation(n)]  # the same scores (tell's 2nd argument), moved
    b = case.make(1)
    b.tell(*shuffled)
    assert np.array_equal(a.ask(10), b.ask(10)) == (not a.adaptive)
    if not a.adaptive:  # nor on constant scores, whichever
        c, d = case.make(1), case.make(1)
        c.tell(data[0], np.zeros(n))
        d.tell(data[0], np.ones(n))
        assert np.array_equal(c.ask(16), d.ask(16))


@pytest.mark.parametrize("case", CASES, ids=repr)
def test_telling_rows_again_counts_them_again_and_keeps_asks_valid(case):
    data, n, once = reference(case)
    twice, again = case.make(1), case.make(1)
    for s in (twice, again):
        s.tell(*data)
        s.tell(*data)
    assert twice.n_told == 2 * n and np.array_equal(twice.X, np.vstack([data[0], data[0]]))
    Q = twice.ask(10)
    assert_valid_ask(twice, Q, 10, case.exact)
    assert np.array_equal(Q, again.ask(10))  # still deterministic
    if not twice.adaptive:
        assert np.array_equal(Q, once.ask(10))


# --------------------------------------------------------------------------- resuming
@pytest.mark.parametrize("case", CASES, ids=repr)
def test_a_resumed_sampler_asks_what_the_original_would(case):
    original, _, tells = drive(case, seed=2, sizes=(10, 14, 9))
    resumed = case.make(2)
    resumed.tell(*joined(*tells))
    resumed.fast_forward(original.n_batches, original.n_asked)
    assert np.array_equal(original.ask(12), resumed.ask(12))


# --------------------------------------------------------------------------- finishing early
class Countdown(Sampler):
    """Random points while ``left`` lasts, then none: the smallest sampler that finishes early."""

    name = "countdown"

    def __init__(self, dim: int, *, seed: int = 0, left: int = 7):
        super().__init__(dim, seed=seed)
        self.left = left

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        m = min(n, self.left)
        self.left -= m
        return rng.random((m, self.dim))


class Overfull(Sampler):
    """Breaks the contract: one point more than asked."""

    def _propose(self, n: int, rng: np.random.Generator) -> np.ndarray:
        return rng.random((n + 1, self.dim))


def assert_finished_for_good(s: Sampler, evaluate: Callable[[np.ndarray], tuple]) -> None:
    """An empty ask finished ``s``: later asks return nothing and count nothing, even after data that
    contradicts what it was told (labels flipped: new boundaries a search would otherwise go after)."""
    batches, asked = s.n_batches, s.n_asked
    assert s.done
    for _ in range(2):
        args = list(evaluate(np.random.default_rng(s.n_told).random((20, s.dim))))
        args[1] = 1.0 - np.asarray(args[1])
        s.tell(*args)
        Q = s.ask(4)
        assert Q.shape == (0, s.dim) and Q.dtype == np.float64
        assert (s.n_batches, s.n_asked, s.done) == (batches, asked, True)


def test_a_sampler_finishes_by_proposing_nothing_and_stays_finished():
    s = Countdown(2, seed=1, left=7)
    assert s.ask(5).shape == (5, 2) and not s.done
    assert s.ask(5).shape == (2, 2) and not s.done  # fewer than asked: allowed, not finished
    Q = s.ask(5)
    assert Q.shape == (0, 2)
    assert (s.n_batches, s.n_asked) == (2, 7)  # the empty ask is no batch
    s.left = 10  # it would propose again: finished is final all the same
    assert_finished_for_good(s, _disk)


def test_a_sampler_proposing_more_than_asked_is_stopped():
    with pytest.raises(RuntimeError, match="expected at most"):
        Overfull(2).ask(3)


@pytest.mark.parametrize("case", [c for c in CASES if c.name.startswith("manifold")], ids=repr)
def test_the_manifold_sampler_finishes_at_its_resolution(case):
    s = case.make(3)
    s.r_min, s.r_max = np.radians(2.0), np.radians(20.0)  # coarse: a short search
    for _ in range(200):
        Q = s.ask(16)
        if not len(Q):
            break
        assert_valid_ask(s, Q, 16, case.exact)
        assert not s.done
        s.tell(*case.evaluate(Q))
    assert_finished_for_good(s, case.evaluate)
    assert 50 < s.n_told < 1000


@pytest.mark.parametrize("case", [c for c in CASES if c.exact], ids=repr)
def test_the_registered_methods_never_finish(case):
    s, asks, _ = drive(case, seed=0, sizes=(40,) * 4)
    assert not s.done and all(len(Q) == 40 for Q in asks)
