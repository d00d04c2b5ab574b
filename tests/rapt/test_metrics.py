"""Tests for rapt.metrics on hand-computed cases and on the synthetic systems."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import qmc

from rapt.metrics import (
    band_reference_points,
    boundary_coverage,
    boundary_precision,
    convergence,
    coverage_curve,
    mean_boundary_distance,
    quality_table,
)
from rapt.testfunctions.composites import Composite8D, Screened
from rapt.testfunctions.shapes import Plates2D, Plates3D, Rings2D


class HalfPlane:
    """2 inputs, boundary x0 = 0.5; only x0 is active, so the band is 1-D."""

    name = "halfplane"
    dim = 2
    n_outputs = 1
    output_types = ("categorical",)
    n_classes = (2,)
    active_dims = ((0,),)

    def __call__(self, X):
        return (np.asarray(X)[:, :1] > 0.5).astype(float)

    def boundary_distance(self, X):
        return np.abs(np.asarray(X)[:, :1] - 0.5)


def hp_points(x0s, x1=0.3):
    x0s = np.asarray(x0s, float)
    return np.c_[x0s, np.full_like(x0s, x1)]


def union_length(centres, d, lo, hi):
    """Exact length of the union of (c - d, c + d) clipped to [lo, hi]."""
    iv = sorted((max(c - d, lo), min(c + d, hi)) for c in centres)
    total, cur_lo, cur_hi = 0.0, None, None
    for a, b in iv:
        if cur_hi is None or a > cur_hi:
            if cur_hi is not None:
                total += cur_hi - cur_lo
            cur_lo, cur_hi = a, b
        else:
            cur_hi = max(cur_hi, b)
    return total + (cur_hi - cur_lo if cur_hi is not None else 0.0)


# -------------------------------------------------------------------------- precision
def test_precision_of_points_at_known_distances():
    s = HalfPlane()
    X = hp_points(0.5 + np.array([0.001, -0.02, 0.029, -0.031, 0.2, -0.4]))
    np.testing.assert_allclose(boundary_precision(s, X, 0.03), [3 / 6])
    np.testing.assert_allclose(boundary_precision(s, X, 0.5), [1.0])
    np.testing.assert_allclose(mean_boundary_distance(s, X), [(0.001 + 0.02 + 0.029 + 0.031 + 0.2 + 0.4) / 6])


def test_precision_radial_points_around_plates2d_disk():
    p = Plates2D()
    (cx, cy), r = p.DISK
    offsets = np.array([0.001, 0.004, 0.02, 0.05, -0.002, -0.008, -0.03, -0.06])
    th = np.linspace(0, 2 * np.pi, len(offsets), endpoint=False)
    X = np.c_[cx + (r + offsets) * np.cos(th), cy + (r + offsets) * np.sin(th)]
    np.testing.assert_allclose(p.boundary_distance(X)[:, 0], np.abs(offsets), atol=1e-12)
    np.testing.assert_allclose(boundary_precision(p, X, 0.01), [4 / 8])


def test_uniform_precision_equals_band_area_of_rings():
    # two circles of radii r1, r2: band area = 4 * pi * d * (r1 + r2)
    r = Rings2D()
    d = 0.01
    X = np.random.default_rng(0).random((200_000, 2))
    expected = 4 * np.pi * d * sum(r.RADII)
    assert abs(boundary_precision(r, X, d)[0] - expected) < 0.002
    comp = Composite8D()
    Xc = np.random.default_rng(1).random((200_000, 8))
    assert abs(boundary_precision(comp, Xc, d)[3] - expected) < 0.002


# --------------------------------------------------------------------------- coverage
def test_coverage_single_sample_half_plane():
    s = HalfPlane()
    # band [0.4, 0.6]; a sample at 0.45 covers [0.4, 0.55): 0.15 / 0.2
    cov = boundary_coverage(s, hp_points([0.45]), 0.1)
    assert abs(cov[0] - 0.75) < 0.015
    # 0.45 and 0.55 cover the whole band
    assert boundary_coverage(s, hp_points([0.45, 0.55]), 0.1)[0] == 1.0
    # a sample outside the band covers nothing, even though it is within d_eps of it
    assert boundary_coverage(s, hp_points([0.35, 0.9]), 0.1)[0] == 0.0


def test_coverage_matches_exact_interval_union():
    s = HalfPlane()
    d = 0.05
    rng = np.random.default_rng(2)
    for _ in range(3):
        c = 0.5 + rng.uniform(-d, d, 4)
        exact = union_length(c, d, 0.5 - d, 0.5 + d) / (2 * d)
        est = boundary_coverage(s, hp_points(c, x1=rng.random()), d, n_reference=20000)[0]
        assert abs(est - exact) < 0.015


def test_coverage_one_for_dense_band_grid_and_zero_far_away():
    p = Plates2D()
    d = 0.02
    g = np.linspace(0, 1, 251)  # spacing 0.004 = d / 5
    G = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    dist = p.boundary_distance(G)[:, 0]
    band = G[dist < d]
    assert boundary_coverage(p, band, d, n_reference=5000)[0] == 1.0
    far = G[dist > 3 * d]
    assert boundary_coverage(p, far, d, n_reference=5000)[0] == 0.0
    assert boundary_precision(p, far, d)[0] == 0.0


def test_coverage_is_deterministic_and_monotone():
    p = Plates2D()
    X = qmc.Sobol(2, scramble=True, seed=0).random(2048)
    d = 0.01
    a = boundary_coverage(p, X[:500], d, n_reference=5000, seed=3)
    np.testing.assert_array_equal(a, boundary_coverage(p, X[:500], d, n_reference=5000, seed=3))
    assert boundary_coverage(p, X[:500], d, n_reference=5000, seed=4)[0] != a[0]
    covs = [boundary_coverage(p, X[:n], d, n_reference=5000, seed=3)[0] for n in (125, 250, 500, 1000, 2048)]
    assert np.all(np.diff(covs) >= 0)
    assert covs[-1] > covs[0] + 0.3
    # adding arbitrary extra samples never lowers coverage
    extra = np.random.default_rng(5).random((300, 2))
    assert boundary_coverage(p, np.vstack([X[:500], extra]), d, n_reference=5000, seed=3)[0] >= a[0]


def test_coverage_curve_agrees_with_coverage():
    comp = Composite8D()
    X = np.random.default_rng(6).random((3000, 8))
    sizes = [0, 100, 1000, 3000]
    curve = coverage_curve(comp, X, 0.02, sizes, n_reference=4000, seed=1)
    assert curve.shape == (4, 4)
    np.testing.assert_array_equal(curve[0], 0.0)
    np.testing.assert_array_equal(curve[-1], boundary_coverage(comp, X, 0.02, n_reference=4000, seed=1))
    np.testing.assert_array_equal(curve[2], boundary_coverage(comp, X[:1000], 0.02, n_reference=4000, seed=1))
    assert np.all(np.diff(curve, axis=0) >= 0)


def test_coverage_uses_only_active_subspace():
    # identical active columns, different noise columns -> identical coverage
    base, screened = Plates3D(), Screened(Plates3D(), 4)
    rng = np.random.default_rng(7)
    X = rng.random((4000, 3))
    Xs = np.c_[X, rng.random((4000, 4))]
    d = 0.03
    c3 = boundary_coverage(base, X, d, n_reference=3000)
    c7 = boundary_coverage(screened, Xs, d, n_reference=3000)
    np.testing.assert_array_equal(c3, c7)
    assert 0 < c3[0] < 1


def test_reference_points_lie_in_band():
    p = Plates3D()
    (R,) = band_reference_points(p, 0.02, n_reference=3000, seed=0)
    assert R.shape == (3000, 3)
    assert np.all(p.boundary_distance(R)[:, 0] < 0.02)
    comp = Composite8D()
    refs = band_reference_points(comp, 0.01, n_reference=1000, seed=0)
    assert [r.shape for r in refs] == [(1000, 2)] * 4
    # capped draws: fewer points, never more
    (R,) = band_reference_points(p, 0.02, n_reference=3000, seed=0, max_draws=10_000)
    assert 0 < len(R) < 3000


# ------------------------------------------------------------------------ convergence
def test_convergence_on_constructed_sequence():
    s = HalfPlane()
    far = [0.1] * 10
    X = hp_points(far + [0.45] + far + [0.55])  # 22 samples; coverage 0.75 at 11, 1.0 at 22
    np.testing.assert_array_equal(convergence(s, X, 0.1, target=0.7, step=1), [11.0])
    np.testing.assert_array_equal(convergence(s, X, 0.1, target=0.9, step=1), [22.0])
    np.testing.assert_array_equal(convergence(s, X, 0.1, target=1.0), [22.0])
    # grid 5, 10, 15, 20, 22
    np.testing.assert_array_equal(convergence(s, X, 0.1, target=0.7, step=5), [15.0])
    np.testing.assert_array_equal(convergence(s, X, 0.1, target=0.9, step=5), [22.0])
    never = convergence(s, hp_points(far), 0.1)
    assert never.dtype == float and np.isnan(never[0])


def test_convergence_per_output():
    comp = Composite8D()
    X = np.random.default_rng(8).random((2000, 8))
    X[:, 6:8] = 0.02  # Rings2D part never sees its band
    out = convergence(comp, X, 0.03, target=0.5, n_reference=3000)
    assert out.shape == (4,)
    assert np.all(np.isfinite(out[:3])) and np.isnan(out[3])
    assert np.all(out[:3] % 100 == 0) and np.all(out[:3] <= 2000)


# --------------------------------------------------------------------- quality table
def test_quality_table_matches_components():
    comp = Composite8D()
    X = np.random.default_rng(9).random((1500, 8))
    t = quality_table(comp, X, 0.02, seed=2, n_reference=3000)
    per = t["per_output"]
    np.testing.assert_array_equal(per["precision"], boundary_precision(comp, X, 0.02))
    np.testing.assert_array_equal(per["coverage"], boundary_coverage(comp, X, 0.02, n_reference=3000, seed=2))
    np.testing.assert_array_equal(per["mean_distance"], mean_boundary_distance(comp, X))
    for key in ("precision", "coverage", "mean_distance"):
        assert isinstance(t[key], float)
        assert t[key] == pytest.approx(per[key].mean())
    assert t["n_samples"] == 1500 and t["d_eps"] == 0.02


# ------------------------------------------------------------------------- validation
@pytest.mark.parametrize("bad", [np.zeros(2), np.zeros((4, 3)), np.zeros((2, 2, 2))])
def test_bad_X_is_rejected(bad):
    p = Plates2D()
    for fn in (boundary_precision, boundary_coverage, convergence, quality_table):
        with pytest.raises(ValueError, match="X must be a 2-D array"):
            fn(p, bad, 0.01)
    with pytest.raises(ValueError, match="X must be a 2-D array"):
        mean_boundary_distance(p, bad)


@pytest.mark.parametrize("d_eps", [0, -0.1, np.nan, np.inf, "0.1", None])
def test_bad_d_eps_is_rejected(d_eps):
    p = Plates2D()
    X = np.random.default_rng(0).random((10, 2))
    for fn in (boundary_precision, boundary_coverage, convergence, quality_table):
        with pytest.raises(ValueError, match="d_eps must be a finite number > 0"):
            fn(p, X, d_eps)


def test_bad_options_are_rejected():
    p = Plates2D()
    X = np.random.default_rng(0).random((10, 2))
    with pytest.raises(ValueError, match="target"):
        convergence(p, X, 0.01, target=0.0)
    with pytest.raises(ValueError, match="target"):
        convergence(p, X, 0.01, target=1.5)
    with pytest.raises(ValueError, match="step"):
        convergence(p, X, 0.01, step=0)
    with pytest.raises(ValueError, match="n_reference"):
        boundary_coverage(p, X, 0.01, n_reference=0)


def test_empty_sample_set():
    p = Plates2D()
    X = np.empty((0, 2))
    assert np.isnan(boundary_precision(p, X, 0.01)[0])
    assert boundary_coverage(p, X, 0.01, n_reference=1000)[0] == 0.0
    assert np.isnan(convergence(p, X, 0.01)[0])
