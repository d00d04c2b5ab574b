"""The quasi-static tipping kernel of planar robots: face identities and the tipping table.

Shared by the per-hull stability function (:mod:`sim.robots.stability`) and the bulk
planar path (:mod:`sim.robots.planar`), so both tip alike; it knows hull faces as arrays
only, not robots or hulls.
"""

from __future__ import annotations

import numpy as np

__all__ = ["GRAVITY", "HASH_BASE", "HASH_MOD", "TOL", "planar_face_ids", "planar_tip_table"]

#: Gravitational acceleration (m/s²) the potential energy is counted with.
GRAVITY = 9.81
#: Relative tolerance of the support tests (scaled by the hull's size).
TOL = 1e-9
HASH_BASE, HASH_MOD = 1_000_003, 2**61 - 1  # face identities: a polynomial hash of the spanning vertices


def planar_face_ids(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Identity of the planar face from canonical vertex ``a`` to ``b`` (an ordered pair: its direction matters).

    The same hash as :meth:`sim.robots.stability.StabilityFunction._face_ids` gives the vertex sequence ``(a, b)``.
    """
    return ((np.asarray(a, dtype=np.int64) + 1) * HASH_BASE + np.asarray(b, dtype=np.int64) + 1) % HASH_MOD


def _rot_xz(v: np.ndarray, c: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Ground-frame (x, z) of base-frame (x, z) points ``v`` (..., 2) under Ry(p), ``c = cos p``, ``s = sin p``."""
    return np.stack([c * v[..., 0] + s * v[..., 1], -s * v[..., 0] + c * v[..., 1]], axis=-1)


def planar_tip_table(
    A: np.ndarray, B: np.ndarray, p: np.ndarray, com: np.ndarray, k: np.ndarray, gravity: np.ndarray, mass: float
) -> tuple[np.ndarray, np.ndarray]:
    """Quasi-static tipping table of n planar hulls: the face each face tips onto and the energy lost, each (n, K).

    Face ``f < k[i]`` of hull ``i`` runs counter-clockwise from ``A[i, f]`` to ``B[i, f]`` (x-z,
    base frame, the next face's start) at body angle ``p[i, f]``; ``com`` (n, 2) is each hull's
    centre of mass; entries ``f >= k[i]`` are padding.  ``next`` is -1 where the face is stable;
    otherwise the robot pivots on the end the centre of mass has crossed onto the neighbouring
    face.  A planar tip depends only on the face it starts from, so following the table from a
    face is the whole quasi-static settling (:meth:`StabilityFunction.settle_all` for one hull,
    :func:`sim.robots.planar.planar_all_faces` for many).
    """
    n, K = p.shape
    f = np.arange(K)[None, :]
    valid = f < k[:, None]
    kk = np.maximum(k, 1)[:, None]
    c, s = np.cos(p), np.sin(p)
    qa, qb, qc = _rot_xz(A, c, s), _rot_xz(B, c, s), _rot_xz(com[:, None, :], c, s)
    gx, gz = gravity[0], gravity[2]
    xs = qc[..., 0] + (qa[..., 1] - qc[..., 1]) / gz * gx  # where the centre of mass meets the ground along gravity
    lo, hi = np.minimum(qa[..., 0], qb[..., 0]), np.maximum(qa[..., 0], qb[..., 0])
    hull_max = np.where(valid[..., None], np.abs(A), 0.0).max(axis=(1, 2))
    tol = (TOL * np.maximum(1.0, hull_max))[:, None]
    over_hi, under_lo = xs > hi + tol, xs < lo - tol
    b_is_hi = qb[..., 0] >= qa[..., 0]
    pivot_b = np.where(over_hi, b_is_hi, ~b_is_hi)  # pivot on vertex b (the next face) or a (the previous)
    nxt = np.where((over_hi | under_lo) & valid, np.where(pivot_b, (f + 1) % kk, (f - 1) % kk), -1)
    pivot = np.where(pivot_b[..., None], B, A)
    j = np.maximum(nxt, 0)
    rows = np.arange(n)[:, None]
    rel = com[:, None, :] - pivot
    up = -gravity[[0, 2]]
    h0 = _rot_xz(rel, c, s) @ up
    h1 = _rot_xz(rel, c[rows, j], s[rows, j]) @ up
    return nxt, np.where(nxt >= 0, mass * GRAVITY * (h0 - h1), 0.0)
