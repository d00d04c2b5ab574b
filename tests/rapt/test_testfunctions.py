"""Tests for rapt.testfunctions: labels, exact boundary distances, noise models."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.stats import norm

from rapt.testfunctions.composites import Composite, Composite8D, Mirrored, Screened
from rapt.testfunctions.geometry import convex_polygon_sdf
from rapt.testfunctions.noise import FuzzyBoundary, GlobalNoise
from rapt.testfunctions.registry import SYSTEMS, get_system
from rapt.testfunctions.shapes import Custom2D, Plates2D, Plates3D, Rings2D

EXPECTED = {
    # name: (dim, output_types, active_dims)
    "custom2d": (2, ("continuous",), ((0, 1),)),
    "plates2d": (2, ("categorical",), ((0, 1),)),
    "plates3d": (3, ("categorical",), ((0, 1, 2),)),
    "plates3d-screened": (7, ("categorical",), ((0, 1, 2),)),
    "composite8d": (
        8,
        ("categorical", "continuous", "categorical", "categorical"),
        ((0, 1), (2, 3), (4, 5), (6, 7)),
    ),
}


# ----------------------------------------------------------------- boundary outlines
def circle_pts(center, r, spacing=1e-4):
    n = int(np.ceil(2 * np.pi * r / spacing))
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[center[0] + r * np.cos(t), center[1] + r * np.sin(t)]


def polyline_pts(vertices, closed=True, spacing=1e-4):
    V = np.asarray(vertices, float)
    if closed:
        V = np.vstack([V, V[:1]])
    out = []
    for a, b in zip(V[:-1], V[1:]):
        n = int(np.ceil(np.linalg.norm(b - a) / spacing)) + 1
        t = np.linspace(0, 1, n)[:, None]
        out.append(a + t * (b - a))
    return np.vstack(out)


def rect_vertices(center, half):
    (cx, cy), (hx, hy) = center, half
    return [(cx - hx, cy - hy), (cx + hx, cy - hy), (cx + hx, cy + hy), (cx - hx, cy + hy)]


def outline_2d(system):
    if isinstance(system, Plates2D):
        (dc, dr), (rc, rh), tri, (ac, ai, ao) = (system.DISK, system.RECT, system.TRIANGLE, system.ANNULUS)
        return np.vstack(
            [
                circle_pts(dc, dr),
                polyline_pts(rect_vertices(rc, rh)),
                polyline_pts(tri),
                circle_pts(ac, ai),
                circle_pts(ac, ao),
            ]
        )
    if isinstance(system, Custom2D):
        c, r = system.CIRCLE
        return np.vstack([circle_pts(c, r), polyline_pts(system.SEGMENT, closed=False)])
    if isinstance(system, Rings2D):
        return np.vstack([circle_pts(system.CENTER, r) for r in system.RADII])
    if isinstance(system, Mirrored):
        P = outline_2d(system.base).copy()
        P[:, list(system.axes)] = 1 - P[:, list(system.axes)]
        return P
    raise TypeError(system)


def grid(lo, hi, spacing):
    n = int(np.ceil((hi - lo) / spacing)) + 1
    return np.linspace(lo, hi, n)


def outline_plates3d(p, s=3e-3):
    pts = []
    # sphere: Fibonacci lattice
    (c, r) = p.SPHERE
    n = int(4 * np.pi * r * r / (s * s)) * 2
    k = np.arange(n) + 0.5
    phi, th = np.arccos(1 - 2 * k / n), np.pi * (1 + 5**0.5) * k
    pts.append(np.c_[np.cos(th) * np.sin(phi), np.sin(th) * np.sin(phi), np.cos(phi)] * r + c)
    # box: grids on the six faces (edges included)
    c, h = np.asarray(p.BOX[0]), np.asarray(p.BOX[1])
    for ax in range(3):
        o1, o2 = [a for a in range(3) if a != ax]
        g1, g2 = np.meshgrid(grid(-h[o1], h[o1], s), grid(-h[o2], h[o2], s))
        for sign in (-1, 1):
            F = np.zeros((g1.size, 3))
            F[:, o1], F[:, o2], F[:, ax] = g1.ravel(), g2.ravel(), sign * h[ax]
            pts.append(F + c)
    # torus (axis x3)
    c, R, r = p.TORUS
    u = np.linspace(0, 2 * np.pi, int(2 * np.pi * (R + r) / s), endpoint=False)
    v = np.linspace(0, 2 * np.pi, int(2 * np.pi * r / s), endpoint=False)
    U, V = np.meshgrid(u, v)
    rho = R + r * np.cos(V)
    pts.append(np.c_[(rho * np.cos(U)).ravel(), (rho * np.sin(U)).ravel(), (r * np.sin(V)).ravel()] + c)
    # capped cylinder (axis x3): side grid + cap grids + rims
    c, r, hh = p.CYLINDER
    t = np.linspace(0, 2 * np.pi, int(2 * np.pi * r / (s / 3)), endpoint=False)
    T, Z = np.meshgrid(t, grid(-hh, hh, s))
    pts.append(np.c_[(r * np.cos(T)).ravel(), (r * np.sin(T)).ravel(), Z.ravel()] + c)
    gx, gy = np.meshgrid(grid(-r, r, s), grid(-r, r, s))
    inside = gx**2 + gy**2 <= r * r
    for z in (-hh, hh):
        pts.append(np.c_[gx[inside], gy[inside], np.full(inside.sum(), z)] + c)
    return np.vstack(pts)


def near_and_uniform(dim, dist_fn, rng, n=4000, band=0.03):
    """Half uniform points, half points within ``band`` of the boundary."""
    X = rng.random((50 * n, dim))
    near = X[dist_fn(X)[:, 0] < band][: n // 2]
    return np.vstack([rng.random((n // 2, dim)), near])


# ------------------------------------------------------------------------- registry
@pytest.mark.parametrize("name", sorted(SYSTEMS))
def test_registry_systems_have_declared_shape(name):
    s = get_system(name)
    dim, types, active = EXPECTED[name]
    assert s.name == name
    assert (s.dim, s.n_outputs, s.output_types, s.active_dims) == (dim, len(types), types, active)
    X = np.random.default_rng(0).random((500, dim))
    Y, D = s(X), s.boundary_distance(X)
    assert Y.shape == D.shape == (500, len(types))
    assert Y.dtype == D.dtype == np.float64
    assert np.all(D >= 0)
    for i, t in enumerate(types):
        if t == "categorical":
            assert np.all(Y[:, i] == np.round(Y[:, i]))
            assert Y[:, i].min() >= 0 and Y[:, i].max() <= s.n_classes[i] - 1


def test_get_system_unknown_name_lists_choices():
    with pytest.raises(ValueError, match=r"unknown system 'nope'; choose one of: .*plates2d"):
        get_system("nope")


@pytest.mark.parametrize("system", [Plates2D(), Plates3D(), Composite8D()])
def test_wrong_input_shape_is_rejected(system):
    with pytest.raises(ValueError, match="shape"):
        system(np.zeros((3, system.dim + 1)))
    with pytest.raises(ValueError, match="shape"):
        system.boundary_distance(np.zeros(system.dim))


@pytest.mark.parametrize("name,n_classes", [("plates2d", 5), ("plates3d", 5), ("plates3d-screened", 5)])
def test_all_classes_occur(name, n_classes):
    s = get_system(name)
    Y = s(np.random.default_rng(1).random((200_000, s.dim)))
    assert s.n_classes == (n_classes,)
    assert set(np.unique(Y[:, 0])) == set(float(c) for c in range(n_classes))


def test_large_batches_are_fast():
    X2 = np.random.default_rng(0).random((1_000_000, 2))
    X3 = np.random.default_rng(0).random((1_000_000, 3))
    t = time.perf_counter()
    Plates2D()(X2)
    Plates3D()(X3)
    Custom2D()(X2)
    assert time.perf_counter() - t < 4.0  # ~1 s on a slow core


# ----------------------------------------------------------------- hand-picked values
def test_plates2d_labels_and_distances_at_known_points():
    p = Plates2D()
    X = np.array(
        [
            [0.22, 0.75],  # disk centre
            [0.68, 0.75],  # rectangle centre
            [0.25, 0.22],  # inside triangle
            [0.78, 0.30],  # annulus ring (radius 0.08)
            [0.70, 0.30],  # annulus hole -> background
            [0.50, 0.50],  # background
            [0.02, 0.02],  # corner
        ]
    )
    np.testing.assert_array_equal(p(X)[:, 0], [1, 2, 3, 4, 0, 0, 0])
    D = p.boundary_distance(X)[:, 0]
    np.testing.assert_allclose(D[[0, 1, 3, 4]], [0.09, 0.07, 0.03, 0.05], atol=1e-12)


def test_plates3d_labels_and_distances_at_known_points():
    p = Plates3D()
    X = np.array(
        [
            [0.25, 0.25, 0.25],  # sphere centre
            [0.72, 0.26, 0.72],  # box centre
            [0.84, 0.70, 0.28],  # torus tube centre line
            [0.70, 0.70, 0.28],  # torus hole -> background
            [0.27, 0.70, 0.68],  # cylinder centre
            [0.50, 0.50, 0.50],  # background
        ]
    )
    np.testing.assert_array_equal(p(X)[:, 0], [1, 2, 3, 0, 4, 0])
    np.testing.assert_allclose(p.boundary_distance(X)[:5, 0], [0.14, 0.11, 0.05, 0.09, 0.12], atol=1e-12)


def test_rings2d_and_mirrored_plates():
    r = Rings2D()
    np.testing.assert_array_equal(r(np.array([[0.55, 0.45], [0.75, 0.45], [0.95, 0.95]]))[:, 0], [2, 1, 0])
    m = Mirrored(Plates2D(), (0, 1))
    # the disk centre (0.22, 0.75) moves to (0.78, 0.25)
    assert m(np.array([[0.78, 0.25]]))[0, 0] == 1
    # (0.30, 0.70) maps to the annulus hole, (0.22, 0.75) onto the annulus ring
    np.testing.assert_array_equal(m(np.array([[0.30, 0.70], [0.22, 0.75]]))[:, 0], [0, 4])


def test_convex_polygon_sdf_unit_square():
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    P = np.array([[0.5, 0.5], [0.5, 0.1], [2.0, 0.5], [2.0, 2.0]])
    np.testing.assert_allclose(convex_polygon_sdf(P, sq), [-0.5, -0.1, 1.0, np.sqrt(2)])


def test_custom2d_landscape_features():
    c = Custom2D()
    (cx, cy), r = c.CIRCLE
    # plateau: flat at PLATEAU inside the circle
    inside = np.array([[cx, cy], [cx + 0.1, cy], [cx, cy - 0.15]])
    np.testing.assert_allclose(c(inside)[:, 0], c.PLATEAU, atol=1e-9)
    # peak and valley are local extrema of the smooth part
    for (px, py), _, amp in c.PEAKS:
        centre = c(np.array([[px, py]]))[0, 0]
        ring = c(np.array([[px + 0.05, py], [px - 0.05, py], [px, py + 0.05], [px, py - 0.05]]))[:, 0]
        assert np.all(ring < centre) if amp > 0 else np.all(ring > centre)
    # cliffs: jumps of ~1 across the circle and across the line
    th = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    u = np.c_[np.cos(th), np.sin(th)]
    jump = c(np.c_[cx, cy] + (r - 0.01) * u)[:, 0] - c(np.c_[cx, cy] + (r + 0.01) * u)[:, 0]
    assert np.all(jump > 0.8) and np.all(jump < 1.6)
    a, b = map(np.asarray, c.SEGMENT)
    n = np.array([(b - a)[1], -(b - a)[0]]) / np.linalg.norm(b - a)
    on = a + np.linspace(0.05, 0.95, 20)[:, None] * (b - a)
    jump = c(on + 0.01 * n)[:, 0] - c(on - 0.01 * n)[:, 0]
    assert np.all(np.abs(jump - 1.0) < 0.15)


def test_custom2d_gradient_is_much_steeper_at_the_cliffs():
    c = Custom2D()
    rng = np.random.default_rng(3)
    X = rng.random((200_000, 2)) * 0.98 + 0.01
    D = c.boundary_distance(X)[:, 0]
    h = 1e-5

    def grad_norm(P):
        gx = (c(P + [h, 0])[:, 0] - c(P - [h, 0])[:, 0]) / (2 * h)
        gy = (c(P + [0, h])[:, 0] - c(P - [0, h])[:, 0]) / (2 * h)
        return np.hypot(gx, gy)

    near, far = X[D < 2e-4], X[D > 0.05]
    assert len(near) > 20 and len(far) > 1000
    g_near, g_far = grad_norm(near), grad_norm(far)
    assert g_near.min() > 100.0
    assert g_far.max() < 5.0
    # the cliff slope peaks on the boundary itself (local max of the first derivative)
    (cx, cy), r = c.CIRCLE
    radii = r + np.linspace(-0.004, 0.004, 81)
    P = np.c_[cx + radii, np.full_like(radii, cy)]
    assert abs(radii[np.argmax(grad_norm(P))] - r) <= 1e-4


# ---------------------------------------------------------- exact boundary distances
@pytest.mark.parametrize(
    "system", [Plates2D(), Custom2D(), Rings2D(), Mirrored(Plates2D(), (0, 1))], ids=lambda s: s.name
)
def test_2d_distance_matches_brute_force(system):
    rng = np.random.default_rng(4)
    X = near_and_uniform(2, system.boundary_distance, rng)
    brute, _ = cKDTree(outline_2d(system)).query(X)
    exact = system.boundary_distance(X)[:, 0]
    # the outline lies on the boundary, so brute >= exact; spacing 1e-4 bounds the gap
    assert np.all(brute - exact >= -1e-12)
    assert np.max(brute - exact) < 2e-4


def test_plates3d_distance_matches_brute_force():
    p = Plates3D()
    rng = np.random.default_rng(5)
    X = near_and_uniform(3, p.boundary_distance, rng, n=3000)
    brute, _ = cKDTree(outline_plates3d(p)).query(X)
    exact = p.boundary_distance(X)[:, 0]
    assert np.all(brute - exact >= -1e-12)
    assert np.max(brute - exact) < 3e-3  # surface grid spacing 3e-3
    far = exact > 0.05
    assert far.sum() > 500
    assert np.max((brute - exact)[far]) < 5e-4


@pytest.mark.parametrize(
    "system", [Plates2D(), Plates3D(), Rings2D(), Mirrored(Plates2D(), (0,))], ids=lambda s: s.name
)
def test_label_constant_within_distance_and_changes_just_beyond(system):
    rng = np.random.default_rng(6)
    X = rng.random((20_000, system.dim))
    d = system.boundary_distance(X)[:, 0]
    u = rng.normal(size=X.shape)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    # every point closer than d has the same label
    Y = X + (0.999 * d * rng.random(len(X)))[:, None] * u
    np.testing.assert_array_equal(system(X), system(Y))
    # points at radius d/2 in many directions too
    for _ in range(5):
        u = rng.normal(size=X.shape)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        np.testing.assert_array_equal(system(X), system(X + 0.5 * d[:, None] * u))
    if system.dim == 2:
        # ... and the label does change somewhere at radius d + 1e-3
        idx = rng.choice(len(X), 150, replace=False)
        th = np.linspace(0, 2 * np.pi, 3600, endpoint=False)
        circ = np.c_[np.cos(th), np.sin(th)]
        for j in idx:
            ring = X[j] + (d[j] + 1e-3) * circ
            assert np.any(system(ring)[:, 0] != system(X[j : j + 1])[0, 0])


def test_composite_stacks_parts():
    comp = Composite8D()
    parts = comp.parts
    X = np.random.default_rng(7).random((3000, 8))
    Y, D = comp(X), comp.boundary_distance(X)
    for i, part in enumerate(parts):
        np.testing.assert_array_equal(Y[:, i], part(X[:, 2 * i : 2 * i + 2])[:, 0])
        np.testing.assert_array_equal(D[:, i], part.boundary_distance(X[:, 2 * i : 2 * i + 2])[:, 0])
    # the four sub-functions really differ
    Z = np.random.default_rng(8).random((3000, 2))
    outs = [p(Z)[:, 0] for p in parts]
    for i in range(4):
        for j in range(i + 1, 4):
            assert not np.array_equal(outs[i], outs[j])
    # changing the inputs of one part leaves the other outputs unchanged
    X2 = X.copy()
    X2[:, 4:6] = np.random.default_rng(9).random((3000, 2))
    Y2 = comp(X2)
    np.testing.assert_array_equal(Y2[:, [0, 1, 3]], Y[:, [0, 1, 3]])
    assert not np.array_equal(Y2[:, 2], Y[:, 2])
    generic = Composite([Plates3D(), Rings2D()])
    assert generic.dim == 5 and generic.active_dims == ((0, 1, 2), (3, 4))


def test_screened_ignores_noise_columns():
    s = Screened(Plates3D(), 4)
    assert s.dim == 7 and s.active_dims == ((0, 1, 2),)
    rng = np.random.default_rng(10)
    X = rng.random((20_000, 7))
    X2 = X.copy()
    X2[:, 3:] = rng.random((20_000, 4))
    np.testing.assert_array_equal(s(X), s(X2))
    np.testing.assert_array_equal(s.boundary_distance(X), s.boundary_distance(X2))
    np.testing.assert_array_equal(s(X), Plates3D()(X[:, :3]))


# ----------------------------------------------------------------------- noisy systems
def test_fuzzy_boundary_is_seeded():
    X = np.random.default_rng(11).random((5000, 2))
    a, b, c = (
        FuzzyBoundary(Plates2D(), 0.02, seed=1),
        FuzzyBoundary(Plates2D(), 0.02, seed=1),
        FuzzyBoundary(Plates2D(), 0.02, seed=2),
    )
    ya, yb, yc = a(X), b(X), c(X)
    np.testing.assert_array_equal(ya, yb)
    assert not np.array_equal(ya, yc)
    assert not np.array_equal(a(X), ya)  # the stream moves on between calls
    a.reset()
    np.testing.assert_array_equal(a(X), ya)
    g = FuzzyBoundary(Plates2D(), 0.02, seed=np.random.default_rng(1))
    np.testing.assert_array_equal(g(X), ya)


def test_fuzzy_boundary_flips_near_not_far():
    sigma = 0.01
    base = Plates2D()
    f = FuzzyBoundary(base, sigma, seed=0)
    X = np.random.default_rng(12).random((400_000, 2))
    d = base.boundary_distance(X)[:, 0]
    flipped = f(X)[:, 0] != base(X)[:, 0]
    near, far = d < 0.1 * sigma, d > 5 * sigma
    assert near.sum() > 1000 and far.sum() > 100_000
    assert flipped[near].mean() > 0.3
    assert flipped[far].mean() < 1e-3
    np.testing.assert_array_equal(f.boundary_distance(X), base.boundary_distance(X))
    # straight edge: flip probability at distance sigma is Phi(-1)
    (cx, cy), (hx, hy) = base.RECT
    P = np.tile([cx, cy + hy + sigma], (20_000, 1))
    rate = (f(P)[:, 0] != 0).mean()
    assert abs(rate - norm.cdf(-1)) < 0.015


def test_fuzzy_boundary_keeps_continuous_outputs_clean():
    comp = Composite8D()
    f = FuzzyBoundary(comp, 0.05, seed=0)
    X = np.random.default_rng(13).random((5000, 8))
    Y, Yc = f(X), comp(X)
    np.testing.assert_array_equal(Y[:, 1], Yc[:, 1])
    for i in (0, 2, 3):
        assert np.any(Y[:, i] != Yc[:, i])


@pytest.mark.parametrize("rate", [0.05, 0.2])
def test_global_noise_rate_and_wrong_class(rate):
    base = Plates2D()
    g = GlobalNoise(base, rate, seed=3)
    X = np.random.default_rng(14).random((20_000, 2))
    clean, noisy = base(X)[:, 0], g(X)[:, 0]
    changed = noisy != clean
    # if a flip could keep the class, the change rate would be 0.8 * rate
    assert abs(changed.mean() - rate) < 4 * np.sqrt(rate * (1 - rate) / len(X))
    assert set(np.unique(noisy)) <= {0.0, 1.0, 2.0, 3.0, 4.0}
    # flips away from background are spread evenly over the four other classes
    new = noisy[changed & (clean == 0)]
    counts = np.array([(new == c).sum() for c in (1, 2, 3, 4)])
    assert counts.min() > 0.7 * counts.mean()
    np.testing.assert_array_equal(g.boundary_distance(X), base.boundary_distance(X))


def test_global_noise_is_seeded_and_leaves_continuous_alone():
    X = np.random.default_rng(15).random((5000, 8))
    a, b, c = (GlobalNoise(Composite8D(), 0.1, seed=s) for s in (5, 5, 6))
    ya, yb, yc = a(X), b(X), c(X)
    np.testing.assert_array_equal(ya, yb)
    assert not np.array_equal(ya, yc)
    np.testing.assert_array_equal(ya[:, 1], Composite8D()(X)[:, 1])
    with pytest.raises(ValueError, match="rate"):
        GlobalNoise(Plates2D(), 1.5)
    with pytest.raises(ValueError, match="sigma"):
        FuzzyBoundary(Plates2D(), -0.1)
