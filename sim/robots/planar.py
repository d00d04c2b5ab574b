"""Every hull face of many joint states of a planar robot at once (the grid search's inner loop).

:meth:`StabilityFunction.all_faces` on a planar robot (Figure 5.2: every joint turns about
the base's y axis) makes Python calls for every joint state: forward kinematics, a Qhull
call and the tipping table.  A grid of a million joint states needs all three in bulk,
so here they are array operations over a chunk of joint states:

* kinematics: in the x-z plane a link's rotation is the sum of its joints' angles;
* hull: edge ``a → b`` of the (deduplicated) vertices is a counter-clockwise hull edge when
  no vertex lies to its right and every vertex on its line lies between ``a`` and ``b``
  (so, as with Qhull, collinear middle points are not vertices); the edges are walked
  into a ring;
* settling: the quasi-static tipping table :meth:`StabilityFunction.settle_all` uses
  (:func:`sim.robots.tipping.planar_tip_table`), followed for every face in step.

The results equal the per-state path's (checked in the tests) up to the order of faces.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from sim.robots.model import Robot
from sim.robots.tipping import planar_face_ids, planar_tip_table

__all__ = ["PlanarFaces", "planar_all_faces"]


class PlanarFaces(Protocol):
    """What :func:`planar_all_faces` reads of a :class:`~sim.robots.stability.StabilityFunction`."""

    robot: Robot
    gravity: np.ndarray  # ground-frame direction of gravity (3,)
    vertex_id: np.ndarray  # per robot vertex, its canonical vertex (coinciding ones share one)


def _kinematics(F: PlanarFaces, theta: np.ndarray, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, V, 2) x-z positions of the kept robot vertices and (n, 2) centre of mass."""
    robot = F.robot
    n = len(theta)
    ang = {robot.base: np.zeros(n)}
    pos = {robot.base: np.zeros((n, 2))}
    for j, a in zip(robot.all_joints, robot.joint_angles(theta).T):
        sign = 1.0 if j.axis[1] > 0 else -1.0
        pa, pp = ang[j.parent], pos[j.parent]
        c, s = np.cos(pa), np.sin(pa)
        ox, oz = j.origin[0], j.origin[2]
        pos[j.child] = pp + np.column_stack([c * ox + s * oz, -s * ox + c * oz])
        ang[j.child] = pa + sign * a
    verts, com = [], np.zeros((n, 2))
    for name, link in robot.links.items():
        v = robot.link_vertices[name][:, [0, 2]]
        c, s = np.cos(ang[name])[:, None], np.sin(ang[name])[:, None]
        t = pos[name]
        verts.append(np.stack([c * v[:, 0] + s * v[:, 1] + t[:, :1], -s * v[:, 0] + c * v[:, 1] + t[:, 1:]], axis=-1))
        m = robot.link_coms[name][[0, 2]]
        com += link.mass * np.column_stack(
            [
                np.cos(ang[name]) * m[0] + np.sin(ang[name]) * m[1] + t[:, 0],
                -np.sin(ang[name]) * m[0] + np.cos(ang[name]) * m[1] + t[:, 1],
            ]
        )
    return np.concatenate(verts, axis=1)[:, keep], com / robot.mass


def _rings(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Counter-clockwise hull rings (n, V) of vertex indices (-1 padded) and their lengths (n,)."""
    n, V, _ = P.shape
    scale = np.abs(P).max(axis=(1, 2))[:, None, None, None]
    d = P[:, None, :, :] - P[:, :, None, :]  # d[s, a, b] = P_b - P_a
    r = P[:, None, None, :, :] - P[:, :, None, None, :]  # r[s, a, _, p] = P_p - P_a
    cross = d[:, :, :, None, 0] * r[..., 1] - d[:, :, :, None, 1] * r[..., 0]  # (n, a, b, p); > 0: p left of a→b
    L2 = (d**2).sum(axis=-1)[..., None]
    t = (d[:, :, :, None, 0] * r[..., 0] + d[:, :, :, None, 1] * r[..., 1]) / np.maximum(L2, 1e-300)
    tol = 1e-9 * np.maximum(scale, 1.0) * np.sqrt(L2)
    right = cross < -tol  # a vertex outside: a→b is no hull edge (counter-clockwise: interior on the left)
    beyond = (np.abs(cross) <= tol) & ((t < -1e-9) | (t > 1 + 1e-9))  # on the line but past an end
    edge = ~(right | beyond).any(axis=3) & (L2[..., 0] > (1e-12 * np.maximum(scale[..., 0], 1.0)) ** 2)
    has = edge.any(axis=2)
    succ = np.where(has, edge.argmax(axis=2), -1)
    start = has.argmax(axis=1)
    ring = -np.ones((n, V), dtype=int)
    cur = start.copy()
    length = np.zeros(n, dtype=int)
    alive = has.any(axis=1)
    rows = np.arange(n)
    for i in range(V):
        ring[alive, i] = cur[alive]
        length += alive
        nxt = succ[rows, cur]
        alive &= (nxt >= 0) & (nxt != start)
        cur = np.maximum(nxt, 0)
    return ring, length


def planar_all_faces(F: PlanarFaces, theta: np.ndarray, chunk: int = 2000) -> dict:
    """Every face of every joint state in ``theta`` (n, m): flat arrays in joint-state order, faces in ring order.

    Keys: ``row`` (joint-state index), ``start``, ``rest`` (body angles, NaN when it rolls
    away), ``stable``, ``energy``, ``tips``, ``start_id``, ``rest_id``, ``count`` (faces per joint state).
    """
    uniq = np.unique(F.vertex_id)
    out: dict[str, list[np.ndarray]] = {
        k: [] for k in ("row", "start", "rest", "stable", "energy", "tips", "start_id", "rest_id", "count")
    }
    for s0 in range(0, len(theta), chunk):
        th = theta[s0 : s0 + chunk]
        P, com = _kinematics(F, th, uniq)
        ring, k = _rings(P)
        n, K = ring.shape
        f = np.arange(K)[None, :]
        valid = f < k[:, None]
        kk = np.maximum(k, 1)[:, None]
        ia = np.where(valid, ring, 0)
        ib = np.take_along_axis(ring, (f + 1) % kk, axis=1)
        ib = np.where(valid, ib, 0)
        rows = np.arange(n)[:, None]
        A, B = P[rows, ia], P[rows, ib]
        d = B - A
        nx, nz = d[..., 1], -d[..., 0]  # outward normal (x, z) of a counter-clockwise edge
        p = np.arctan2(nx, -nz)
        nxt, step = planar_tip_table(A, B, p, com, k, F.gravity, F.robot.mass)
        g = np.broadcast_to(f, (n, K)).copy()  # follow the table for every face in step
        energy = np.zeros((n, K))
        tips = np.zeros((n, K), dtype=int)
        for _ in range(K + 2):
            ng = np.take_along_axis(nxt, g, axis=1)
            go = (ng >= 0) & (tips <= k[:, None])
            if not go.any():
                break
            energy += np.where(go, np.take_along_axis(step, g, axis=1), 0.0)
            g = np.where(go, ng, g)
            tips += go
        rolls = np.take_along_axis(nxt, g, axis=1) >= 0
        fid = planar_face_ids(uniq[ia], uniq[ib])
        rest_p = np.where(rolls, np.nan, np.take_along_axis(p, g, axis=1))
        rest_id = np.where(rolls, -1, np.take_along_axis(fid, g, axis=1))
        m = valid
        out["row"].append(np.broadcast_to(np.arange(s0, s0 + n)[:, None], (n, K))[m])
        out["start"].append(p[m])
        out["rest"].append(rest_p[m])
        out["stable"].append((tips == 0)[m])
        out["energy"].append(np.where(rolls, np.inf, energy)[m])
        out["tips"].append(tips[m])
        out["start_id"].append(fid[m].astype(np.int64))
        out["rest_id"].append(rest_id[m].astype(np.int64))
        out["count"].append(k)
    return {key: np.concatenate(v) if v else np.empty(0) for key, v in out.items()}


def planar_snap(F: PlanarFaces, theta: np.ndarray, phi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Algorithm 5's snap and stability test for many states ``[θ, φ]`` of a planar robot, without their hulls.

    Returns the snapped face's body angle (n,), whether that face is stable (n,) and its identity
    (n,): the same ``start``, ``stable`` and ``start_id`` as :meth:`StabilityFunction.__call__`
    (checked in the tests), at a
    fraction of the cost, which a PRM local planner checking millions of path states needs.
    The face nearest ``φ``'s down direction ``d`` is one of the two hull edges at the vertex
    extreme along ``d``; each is found as the neighbour making the smallest turn from the
    tangent (collinear points: the farthest, as Qhull keeps only the ends).
    """
    theta = np.asarray(theta, dtype=float).reshape(-1, F.robot.dof)
    phi = np.asarray(phi, dtype=float).reshape(-1)
    uniq = np.unique(F.vertex_id)
    P, com = _kinematics(F, theta, uniq)
    n = len(P)
    d = np.column_stack([np.sin(phi), -np.cos(phi)])  # down direction (x, z), base frame
    t = np.column_stack([d[:, 1], -d[:, 0]])  # tangent: d turned by -90°
    rows = np.arange(n)
    s = np.argmax(np.einsum("nvk,nk->nv", P, d), axis=1)
    w = P - P[rows, s][:, None, :]
    length = np.linalg.norm(w, axis=2)
    ang = np.arctan2(-np.einsum("nvk,nk->nv", w, d), np.einsum("nvk,nk->nv", w, t))  # in [0, π] (s is extreme)
    ang = np.where(ang < -np.pi / 2, np.pi, np.maximum(ang, 0.0))  # round-off below the tangent (a tied extreme)
    scale = np.maximum(length.max(axis=1, keepdims=True), 1e-300)
    real = length > 1e-12 * scale
    tie = 1e-12 * length / scale  # nearly equal turns: the farther point spans the face
    a_idx = np.argmin(np.where(real, ang - tie, np.inf), axis=1)
    b_idx = np.argmax(np.where(real, ang + tie, -np.inf), axis=1)
    a, b = ang[rows, a_idx], ang[rows, b_idx]
    # outward normals of the two edges at s (the polygon lies between their turns a and b, seen from s)
    n_a = np.sin(a)[:, None] * t + np.cos(a)[:, None] * d
    n_b = -np.sin(b)[:, None] * t - np.cos(b)[:, None] * d
    first = np.cos(a) >= -np.cos(b)  # n_a · d against n_b · d: the face most nearly facing the ground
    other = np.where(first, a_idx, b_idx)
    normal = np.where(first[:, None], n_a, n_b)
    start = np.arctan2(normal[:, 0], -normal[:, 1])
    # the hull runs counter-clockwise along (-n_z, n_x): does the face run from s to the other end, or back?
    forward = np.einsum("nk,nk->n", P[rows, other] - P[rows, s], np.column_stack([-normal[:, 1], normal[:, 0]])) > 0
    ia, ib = np.where(forward, s, other), np.where(forward, other, s)
    A, B = P[rows, ia][:, None, :], P[rows, ib][:, None, :]
    nxt, _ = planar_tip_table(A, B, start[:, None], com, np.ones(n, dtype=int), F.gravity, F.robot.mass)
    return start, nxt[:, 0] < 0, planar_face_ids(uniq[ia], uniq[ib]).astype(np.int64)
