"""What each sampler does beyond the shared contract (that is tests/rapt/test_sampler_contract.py)."""

import numpy as np
import pytest

from rapt.samplers import make_sampler
from tests.support.systems import disk, disk_distance, two_outputs

ADAPTIVE = ["gpr", "nndv", "s-ndv"]


def run(method, steps=6, n=50, seed=0, dim=2, fn=disk, **opts):
    s = make_sampler(method, dim, seed=seed, **opts)
    for _ in range(steps):
        X = s.ask(n)
        assert X.shape == (n, dim)
        assert np.all((X >= 0) & (X <= 1))
        s.tell(X, fn(X))
    return s


@pytest.mark.parametrize("method", ADAPTIVE)
def test_adaptive_samplers_concentrate_on_the_boundary(method):
    steps = 6 if method == "gpr" else 10
    s = run(method, steps=steps, n=50, seed=1)
    sobol = run("sobol", steps=steps, n=50, seed=1)
    adaptive_precision = np.mean(disk_distance(s.X) < 0.02)
    sobol_precision = np.mean(disk_distance(sobol.X) < 0.02)
    assert adaptive_precision > 2.5 * sobol_precision


@pytest.mark.parametrize("method", ADAPTIVE)
def test_batches_have_no_near_duplicates(method):
    s = run(method, steps=3, n=60, seed=2)
    X = s.ask(60)
    d = np.sqrt(((X[:, None, :] - X[None, :, :]) ** 2).sum(-1)) + np.eye(60)
    assert d.min() > 1e-4


def test_sobol_continues_one_sequence_across_batches():
    s = make_sampler("sobol", 2, seed=3)
    joined = np.vstack([s.ask(8), s.ask(8)])
    whole = make_sampler("sobol", 2, seed=3).ask(16)
    assert np.allclose(joined, whole)


def test_lhs_with_size_is_one_latin_hypercube():
    s = make_sampler("lhs", 2, seed=0, size=40)
    X = np.vstack([s.ask(10) for _ in range(4)])
    for j in range(2):
        assert sorted(np.floor(X[:, j] * 40).astype(int).tolist()) == list(range(40))


def test_scaled_ndv_learns_which_inputs_matter_per_output():
    s = run("s-ndv", steps=8, n=100, seed=0, dim=4, fn=two_outputs)
    w = s.weights_
    assert w.shape == (2, 4)
    assert w[0].argmax() == 0 and w[0, 1:].max() < 0.2
    assert w[1].argmax() == 2 and np.delete(w[1], 2).max() < 0.2
    assert s.output_types == ("binary", "continuous")


def test_tell_accepts_states_other_than_asked_and_failures():
    s = make_sampler("nndv", 2, seed=0)
    X = s.ask(30)
    snapped = np.round(X, 1)
    s.tell(snapped, disk(snapped))
    assert np.array_equal(s.X, snapped)
    s.tell_failed(X[:3])
    assert s.X_failed.shape == (3, 2) and s.n_told == 30


def test_pluggable_candidate_generator_is_used():
    class OnDiagonal:
        def __call__(self, n, rng, sampler):
            t = rng.random(n)
            return np.column_stack([t, t])

    s = make_sampler("nndv", 2, seed=0, candidate_generator=OnDiagonal())
    X = s.ask(40)
    s.tell(X, disk(X))
    X2 = s.ask(40)
    assert np.allclose(X2[:, 0], X2[:, 1])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"k": 1}, "k: need at least 2"),
        ({"g": -1}, "g: expected"),
        ({"candidates_per_point": 1}, "p > L"),
        ({"candidate_generator": 3}, "candidate_generator"),
    ],
)
def test_bad_sampler_options(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_sampler("nndv", 2, **kwargs)


def test_tell_validation():
    s = make_sampler("nndv", 2)
    with pytest.raises(ValueError, match="X: expected shape"):
        s.tell(np.zeros((3, 3)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="Y: scores must be finite"):
        s.tell(np.zeros((2, 2)), np.array([[1.0], [np.nan]]))
    with pytest.raises(ValueError, match="Y: expected one score row"):
        s.tell(np.zeros((2, 2)), np.zeros((3, 1)))
    with pytest.raises(ValueError, match="unknown method 'tpe'"):
        make_sampler("tpe", 2)


def test_max_reference_bounds_the_neighbour_set_deterministically():

    def told(**kw):
        s = make_sampler("s-ndv", 2, seed=5, output_types=("binary",), **kw)
        X = np.random.default_rng(0).random((600, 2))
        s.tell(X, disk(X))
        return s

    capped = told(max_reference=100)
    X_ref, targets = capped._reference(np.random.default_rng(1))
    assert X_ref.shape == (100, 2) and targets[0][1].shape == (100,)
    assert told()._reference(np.random.default_rng(1))[0].shape == (600, 2)  # off by default
    a, b = told(max_reference=100).ask(50), told(max_reference=100).ask(50)
    np.testing.assert_array_equal(a, b)  # seeded: the same subset, the same batch
    near = np.abs(np.hypot(a[:, 0] - 0.5, a[:, 1] - 0.5) - 0.3)
    assert np.median(near) < 0.08  # still drawn to the circle from a sixth of the data
    with pytest.raises(ValueError, match="max_reference"):
        make_sampler("nndv", 2, max_reference=8)
