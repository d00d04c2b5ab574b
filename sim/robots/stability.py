"""The self-righting stability function (Algorithm 5): hull faces, snapping, quasi-static tipping.

For a joint state θ the robot can touch a plane only with its convex hull, so its possible
resting orientations are the hull's faces.  A face is written as a *body angle*: the
orientation of the base that puts the face flat on the ground.  A query ``[θ, φ]`` is
snapped to the face whose down direction is nearest to φ's (the projection onto the
constraint manifold, section 5.4.2), then tipped quasi-statically — rotated about the
support-polygon edge the centre of mass has crossed, onto the neighbouring face — until the
centre of mass projects (along gravity) inside the support polygon.

Body angles.  The ground plane is tilted by ``slope`` about its y axis (downhill is +x);
yaw relative to the fall line is not a state (it is 0 at the start of a tip).
* Planar robots (every joint turns about the base y axis, Figure 5.2) have one body
  angle, the pitch ``p``: the face's outward normal is ``(sin p, 0, -cos p)``.  Hulls are
  computed in the x-z plane (the extruded 3-D hull's side faces are the same faces).
* Other robots have two, ``(roll, pitch)`` with the base orientation ``Ry(pitch) Rx(roll)``:
  the face normal is ``(sin p, -sin r cos p, -cos r cos p)``, pitch in [-90°, 90°].

Face identity.  Each face also gets an integer id naming the robot vertices that span it
(box corners and mesh vertices keep their index for every θ; in a planar robot the two
corners that differ only in y count as one).  The same id at two joint states is the same
face — section 5.2's "pair of unique vertices" — which Algorithm 8 uses to keep
neighbouring but different faces apart.

Potential energy lost is ``M g Δh`` of the centre of mass, measured with every pivot edge
held fixed on the ground, so a tip downhill on a slope loses more than the same tip uphill.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from rapt.errors import InputError
from sim.robots.model import Robot, rotation
from sim.robots.planar import planar_all_faces
from sim.robots.tipping import GRAVITY, HASH_BASE, HASH_MOD, TOL, planar_face_ids, planar_tip_table

__all__ = ["Hull", "StabilityResult", "StabilityFunction", "body_angles", "down_normals"]


def body_angles(normals: np.ndarray, planar: bool) -> np.ndarray:
    """Body angles (k, 1) or (k, 2) of outward face normals (k, 3) in the base frame."""
    n = np.asarray(normals, dtype=float).reshape(-1, 3)
    if planar:
        return np.arctan2(n[:, 0], -n[:, 2])[:, None]
    pitch = np.arcsin(np.clip(n[:, 0], -1.0, 1.0))
    side = np.hypot(n[:, 1], n[:, 2]) < 1e-9  # pitch ±90°: roll is free (gimbal lock); take 0
    roll = np.where(side, 0.0, np.arctan2(-n[:, 1], -n[:, 2]))
    return np.column_stack([roll, pitch])


def down_normals(angles: np.ndarray, planar: bool) -> np.ndarray:
    """Inverse of :func:`body_angles`: the base-frame direction that points at the ground."""
    a = np.asarray(angles, dtype=float)
    if planar:
        p = a.reshape(-1)
        return np.column_stack([np.sin(p), np.zeros_like(p), -np.cos(p)])
    a = a.reshape(-1, 2)
    r, p = a[:, 0], a[:, 1]
    return np.column_stack([np.sin(p), -np.sin(r) * np.cos(p), -np.cos(r) * np.cos(p)])


def _orientation(angles: np.ndarray, planar: bool) -> np.ndarray:
    """Base-to-ground rotation with yaw 0 for one body angle."""
    if planar:
        return rotation(np.array([0.0, 1.0, 0.0]), float(angles[0]))
    return rotation(np.array([0.0, 1.0, 0.0]), float(angles[1])) @ rotation(np.array([1.0, 0.0, 0.0]), float(angles[0]))


@dataclass
class Hull:
    """The convex hull of the robot at one joint state, as faces it could rest on."""

    theta: np.ndarray
    points: np.ndarray  # hull vertices (base frame)
    com: np.ndarray
    normals: np.ndarray  # (k, 3) outward unit normals
    offsets: np.ndarray  # (k,) plane offsets: normal · x + offset = 0 on the face
    face_vertices: list  # per face: indices into points (ordered around the face for planar hulls)
    angles: np.ndarray  # (k, b) body angles
    ids: np.ndarray  # (k,) face identities (see the module docstring)
    ordered: bool = True

    def __post_init__(self) -> None:
        self._rings: dict[int, np.ndarray] = {}

    @property
    def n_faces(self) -> int:
        return len(self.normals)

    def ring(self, f: int) -> np.ndarray:
        """Vertices of face ``f`` counter-clockwise seen from outside; ordered on first use (few faces ever are)."""
        if self.ordered:
            return self.face_vertices[f]
        if f not in self._rings:
            self._rings[f] = StabilityFunction._ordered(self.points, self.face_vertices[f], self.normals[f])
        return self._rings[f]


@dataclass
class StabilityResult:
    """Algorithm 5's output ``[X, Y, W]`` for n queries."""

    theta: np.ndarray  # (n, m) joint states
    start: np.ndarray  # (n, b) snapped starting body angles φ_S
    stable: np.ndarray  # (n,) bool
    rest: np.ndarray  # (n, b) resting body angles φ_R
    energy: np.ndarray  # (n,) potential energy lost, J
    faces: list  # per query: (k_i, b) hull faces Z_θ as body angles
    tips: np.ndarray  # (n,) number of tips until rest
    start_id: np.ndarray  # (n,) face identity of the starting face
    rest_id: np.ndarray  # (n,) face identity of the resting face (-1 when it never rests)
    face_ids: list  # per query: (k_i,) identities of the faces in ``faces``

    def __len__(self) -> int:
        return len(self.stable)


class StabilityFunction:
    """``F(θ, φ)`` of Algorithm 5 for one robot on a plane of ``slope_deg`` degrees.

    ``planar=None`` follows :attr:`Robot.planar`; ``False`` forces the 3-D hull and
    (roll, pitch) body angles even for a planar robot.
    """

    def __init__(self, robot: Robot, slope_deg: float = 0.0, planar: bool | None = None):
        if not (0.0 <= slope_deg < 90.0):
            raise InputError(f"slope: expected degrees in [0, 90), got {slope_deg}")
        self.robot = robot
        self.slope = float(np.radians(slope_deg))
        self.planar = robot.planar if planar is None else bool(planar)  # planar=False forces 3-D hulls
        self.n_body = 1 if self.planar else 2
        self.gravity = np.array([np.sin(self.slope), 0.0, -np.cos(self.slope)])  # ground frame
        self.n_queries = 0
        self.n_hulls = 0
        self.vertex_id = self._canonical_vertices()

    def _canonical_vertices(self) -> np.ndarray:
        """Per robot vertex, the index of the first vertex it always coincides with in the hull's plane.

        A planar hull sees a box corner and its mirror in y as one point, so both get one id;
        in 3-D every vertex is its own.  Checked at two joint states so chance overlaps do not merge.
        """
        rng = np.random.default_rng(0)
        lo_hi = self.robot.joint_bounds
        keys = []
        for _ in range(2):
            th = lo_hi[:, 0] + rng.random(self.robot.dof) * (lo_hi[:, 1] - lo_hi[:, 0])
            v, _ = self.robot.geometry(th)
            keys.append(np.round(v[:, [0, 2]] if self.planar else v, 9))
        key = np.concatenate(keys, axis=1)
        _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
        return first[inv.reshape(-1)]

    @staticmethod
    def _face_ids(vertex_sets) -> np.ndarray:
        """Integer identity of each 3-D face from the set of (canonical) robot vertices spanning it.

        Planar faces are ordered pairs: :func:`planar_face_ids`, the same hash of the pair.
        """
        out = np.empty(len(vertex_sets), dtype=np.int64)
        for i, vs in enumerate(vertex_sets):
            h = 0
            for v in sorted(set(vs)):
                h = (h * HASH_BASE + int(v) + 1) % HASH_MOD
            out[i] = h
        return out

    # -- hull ------------------------------------------------------------------------------
    def hull(self, theta: np.ndarray) -> Hull:
        """Faces of the convex hull at joint state ``theta``."""
        verts, com = self.robot.geometry(theta)
        self.n_hulls += 1
        return self._hull2d(theta, verts, com) if self.planar else self._hull3d(theta, verts, com)

    def _hull2d(self, theta, verts, com) -> Hull:
        xz = verts[:, [0, 2]]
        h = ConvexHull(xz)
        ring = h.vertices  # counter-clockwise in (x, z)
        pts = np.column_stack([xz[ring, 0], np.zeros(len(ring)), xz[ring, 1]])
        a, b = pts, np.roll(pts, -1, axis=0)
        d = b - a
        normals = np.column_stack([d[:, 2], np.zeros(len(d)), -d[:, 0]])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        offsets = -(normals * a).sum(axis=1)
        k = len(ring)
        faces = [np.array([i, (i + 1) % k]) for i in range(k)]
        vid = self.vertex_id[ring]
        ids = planar_face_ids(vid, np.concatenate([vid[1:], vid[:1]]))  # each face runs from vertex i to i + 1
        return Hull(
            np.asarray(theta, float),
            pts,
            np.array([com[0], 0.0, com[2]]),
            normals,
            offsets,
            faces,
            body_angles(normals, True),
            ids=ids,
        )

    def _hull3d(self, theta, verts, com) -> Hull:
        h = ConvexHull(verts)
        eq = h.equations
        scale = max(np.ptp(verts, axis=0).max(), 1e-12)
        key = eq / np.array([1.0, 1.0, 1.0, scale])
        close = np.abs(key[:, None, :] - key[None, :, :]).max(axis=2) < 1e-7  # coplanar triangles
        group = -np.ones(len(eq), dtype=int)
        n_groups = 0
        for i in range(len(eq)):
            if group[i] < 0:
                group[close[i] & (group < 0)] = n_groups
                n_groups += 1
        used = np.unique(h.simplices)
        remap = -np.ones(len(verts), dtype=int)
        remap[used] = np.arange(len(used))
        pts = verts[used]
        sums = np.zeros((n_groups, 4))
        np.add.at(sums, group, eq)
        normals = sums[:, :3] / np.linalg.norm(sums[:, :3], axis=1, keepdims=True)
        offsets = sums[:, 3] / np.bincount(group, minlength=n_groups)
        pairs = np.unique(np.column_stack([np.repeat(group, 3), remap[h.simplices].ravel()]), axis=0)
        faces = np.split(pairs[:, 1], np.flatnonzero(np.diff(pairs[:, 0])) + 1)
        ids = self._face_ids([self.vertex_id[used[f]] for f in faces])
        return Hull(
            np.asarray(theta, float),
            pts,
            com,
            normals,
            np.asarray(offsets),
            faces,
            body_angles(normals, False),
            ordered=False,
            ids=ids,
        )

    @staticmethod
    def _ordered(pts: np.ndarray, idx: np.ndarray, n: np.ndarray) -> np.ndarray:
        """Face vertices in counter-clockwise order seen from outside (extreme points only)."""
        u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        uv = np.column_stack([pts[idx] @ u, pts[idx] @ v])
        if len(idx) == 3:
            ring = np.arange(3)
        else:
            try:
                ring = ConvexHull(uv).vertices
            except QhullError:  # numerically degenerate sliver: keep the angular order
                c = uv.mean(axis=0)
                ring = np.argsort(np.arctan2(uv[:, 1] - c[1], uv[:, 0] - c[0]))
        ordered = idx[ring]
        p = pts[ordered]
        if np.dot(np.cross(p[1] - p[0], p[2] - p[0]), n) < 0:
            ordered = ordered[::-1]
        return ordered

    # -- snapping and tipping ----------------------------------------------------------------
    def snap(self, hull: Hull, phi: np.ndarray) -> int:
        """Index of the face whose down direction is nearest to body angle ``phi``."""
        down = down_normals(np.asarray(phi, float).reshape(1, -1), self.planar)[0]
        return int(np.argmax(hull.normals @ down))

    def settle(self, hull: Hull, face: int) -> tuple[int, float, int]:
        """Tip quasi-statically from ``face`` until stable: (resting face, energy lost in J, tips)."""
        R = _orientation(hull.angles[face], self.planar)
        up = -self.gravity
        c = hull.com
        energy, tips = 0.0, 0
        while True:
            n = hull.normals[face]
            ring = hull.ring(face)
            g_b = R.T @ self.gravity
            t = (-hull.offsets[face] - n @ c) / (n @ g_b)
            cp = c + t * g_b  # centre of mass projected along gravity onto the face plane
            a = hull.points[ring]
            b = hull.points[np.roll(ring, -1)]
            if self.planar:  # the face is a segment; its "edges" are its end points, outward along it
                outward = a - b
                pivots = list(zip(ring, ring))
            else:
                outward = np.cross(b - a, n)
                pivots = list(zip(ring, np.roll(ring, -1)))
            outward /= np.linalg.norm(outward, axis=1, keepdims=True)
            excess = ((cp - a) * outward).sum(axis=1)
            e = int(np.argmax(excess))
            if excess[e] <= TOL * max(1.0, np.abs(a).max()):
                return face, energy, tips
            if tips > 4 * hull.n_faces + 8:  # no stable face on this slope: it rolls away downhill
                return -1, float("inf"), tips
            ia, ib = pivots[e]
            nxt = self._across(hull, face, ia, ib)
            w = R @ (np.array([0.0, 1.0, 0.0]) if self.planar else hull.points[ib] - hull.points[ia])
            w /= np.linalg.norm(w)
            v1 = R @ hull.normals[nxt]
            target = np.array([0.0, 0.0, -1.0])
            angle = np.arctan2(w @ np.cross(v1, target), v1 @ target)
            R2 = rotation(w, angle) @ R
            energy += self.robot.mass * GRAVITY * float(up @ ((R - R2) @ (c - hull.points[ia])))
            R, face, tips = R2, nxt, tips + 1

    def settle_all(self, hull: Hull) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`settle` from every face: (resting face, energy, tips) arrays.

        Planar hulls are done in one vectorised pass (a planar tip depends only on the face
        it starts from, so chains of tips are followed through a table); 3-D hulls face by face.
        """
        k = hull.n_faces
        if not self.planar:
            out = [self.settle(hull, f) for f in range(k)]
            return (
                np.array([o[0] for o in out]),
                np.array([o[1] for o in out], dtype=float),
                np.array([o[2] for o in out]),
            )
        P = hull.points[:, [0, 2]]
        nxt, step = planar_tip_table(
            P[None],
            np.concatenate([P[1:], P[:1]])[None],
            hull.angles[None, :, 0],
            hull.com[None, [0, 2]],
            np.array([k]),
            self.gravity,
            self.robot.mass,
        )
        nxt, step = nxt[0].tolist(), step[0].tolist()
        rest = np.empty(k, dtype=int)
        energy = np.empty(k)
        tips = np.empty(k, dtype=int)
        for f in range(k):  # follow the table (planar_all_faces does the same in bulk)
            g, e, t = f, 0.0, 0
            while nxt[g] >= 0 and t <= k:
                e += step[g]
                g = nxt[g]
                t += 1
            rest[f], energy[f], tips[f] = (g, e, t) if nxt[g] < 0 else (-1, np.inf, t)
        return rest, energy, tips

    @staticmethod
    def _across(hull: Hull, face: int, ia: int, ib: int) -> int:
        """The face sharing edge (ia, ib) with ``face``: the one the robot lands on when tipping over it."""
        for f, ring in enumerate(hull.face_vertices):
            if f != face and ia in ring and ib in ring:
                return f
        # degenerate hull (an edge split by a near-collinear vertex): the face most nearly
        # perpendicular to the edge among those touching one of its ends
        edge = hull.points[ib] - hull.points[ia]
        edge /= np.linalg.norm(edge)
        cand = [f for f, ring in enumerate(hull.face_vertices) if f != face and (ia in ring or ib in ring)]
        return min(cand, key=lambda f: (abs(hull.normals[f] @ edge), -(hull.normals[f] @ hull.normals[face])))

    # -- Algorithm 5 ------------------------------------------------------------------------
    def __call__(self, theta: np.ndarray, phi: np.ndarray) -> StabilityResult:
        """Evaluate queries ``[θ_i, φ_i]``: snap each to its nearest face, tip until stable."""
        phi = np.asarray(phi, dtype=float).reshape(-1, self.n_body)
        theta = np.asarray(theta, dtype=float).reshape(len(phi), self.robot.dof)
        n = len(theta)
        start = np.empty((n, self.n_body))
        rest = np.empty((n, self.n_body))
        energy = np.empty(n)
        tips = np.empty(n, dtype=int)
        start_id, rest_id = np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64)
        faces, face_ids = [], []
        for i in range(n):
            hull = self.hull(theta[i])
            f0 = self.snap(hull, phi[i])
            if self.planar:
                r_all, e_all, t_all = self.settle_all(hull)
                f1, energy[i], tips[i] = r_all[f0], e_all[f0], t_all[f0]
            else:
                f1, energy[i], tips[i] = self.settle(hull, f0)
            start[i] = hull.angles[f0]
            rest[i] = hull.angles[f1] if f1 >= 0 else np.nan
            start_id[i], rest_id[i] = hull.ids[f0], hull.ids[f1] if f1 >= 0 else -1
            faces.append(hull.angles)
            face_ids.append(hull.ids)
        self.n_queries += n
        return StabilityResult(theta, start, tips == 0, rest, energy, faces, tips, start_id, rest_id, face_ids)

    def all_faces(self, theta: np.ndarray) -> StabilityResult:
        """Every hull face of every joint state as a starting state (the grid search's queries)."""
        theta = np.asarray(theta, dtype=float)
        theta = theta.reshape(theta.shape[0] if theta.ndim == 2 else -1, self.robot.dof)
        if self.planar and len(theta):
            return self._all_faces_planar(theta)
        # per joint state: its faces' rows of the result, concatenated below
        row_parts: list[np.ndarray] = []
        start_parts: list[np.ndarray] = []
        rest_parts: list[np.ndarray] = []
        energy_parts: list[np.ndarray] = []
        tips_parts: list[np.ndarray] = []
        start_id_parts: list[np.ndarray] = []
        rest_id_parts: list[np.ndarray] = []
        faces: list[np.ndarray] = []
        face_ids: list[np.ndarray] = []
        for th in theta:
            hull = self.hull(th)
            r_all, e_all, t_all = self.settle_all(hull)
            k = hull.n_faces
            row_parts.append(np.broadcast_to(th, (k, len(th))))
            start_parts.append(hull.angles)
            rest_parts.append(np.where((r_all >= 0)[:, None], hull.angles[np.maximum(r_all, 0)], np.nan))
            energy_parts.append(e_all)
            tips_parts.append(t_all)
            faces.extend([hull.angles] * k)
            start_id_parts.append(hull.ids)
            rest_id_parts.append(np.where(r_all >= 0, hull.ids[np.maximum(r_all, 0)], -1))
            face_ids.extend([hull.ids] * k)
        rows, start, rest = (
            np.concatenate(v) if v else np.empty((0, w))
            for v, w in ((row_parts, self.robot.dof), (start_parts, self.n_body), (rest_parts, self.n_body))
        )
        energy = np.concatenate(energy_parts) if energy_parts else np.empty(0)
        tips = np.concatenate(tips_parts).astype(int) if tips_parts else np.empty(0, dtype=int)
        self.n_queries += len(tips)
        ids = [
            np.concatenate(v).astype(np.int64) if v else np.empty(0, dtype=np.int64)
            for v in (start_id_parts, rest_id_parts)
        ]
        return StabilityResult(rows, start, tips == 0, rest, energy, faces, tips, ids[0], ids[1], face_ids)

    def _all_faces_planar(self, theta: np.ndarray) -> StabilityResult:
        """:meth:`all_faces` for a planar robot, in bulk (:mod:`sim.robots.planar`); same results."""
        b = planar_all_faces(self, theta)
        self.n_hulls += len(theta)
        self.n_queries += len(b["row"])
        cuts = np.cumsum(b["count"])[:-1]
        per_hull = np.split(b["start"][:, None], cuts)
        ids = np.split(b["start_id"], cuts)
        faces = [f for f, k in zip(per_hull, b["count"]) for _ in range(k)]
        face_ids = [f for f, k in zip(ids, b["count"]) for _ in range(k)]
        return StabilityResult(
            theta[b["row"]],
            b["start"][:, None],
            b["stable"].astype(bool),
            b["rest"][:, None],
            b["energy"],
            faces,
            b["tips"].astype(int),
            b["start_id"],
            b["rest_id"],
            face_ids,
        )
