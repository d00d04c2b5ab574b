"""Rigid-body robot models for self-righting analysis (chapter 5): links on revolute joints.

A robot is a tree of links rooted at the base (the body whose orientation is the "body
angle").  Each link carries collision geometry — boxes and optionally STL meshes — and a
mass; only the vertices matter, because a robot on a plane can touch the ground only with
points on its convex hull.  Forward kinematics gives every vertex and the centre of mass in
the base frame for a joint state θ.

The model reads no files: robot files (TOML, :mod:`sim.robots.robotfile`; a URDF subset,
:mod:`sim.robots.urdf`) are read into it.  A malformed robot raises :class:`RobotFileError`.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from rapt.errors import FileFormatError, InputError

__all__ = ["RobotFileError", "Box", "Link", "Joint", "Robot", "rotation"]


class RobotFileError(FileFormatError):
    """A robot file is malformed; the message names the field and what is expected.

    A :class:`rapt.errors.FileFormatError`, so also an ``InputError``, a ``RaptError`` and a ``ValueError``.
    """


@dataclass(frozen=True)
class Box:
    size: tuple[float, float, float]
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def vertices(self) -> np.ndarray:
        half = np.asarray(self.size) / 2.0
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
        return np.asarray(self.center) + signs * half

    @property
    def volume(self) -> float:
        return float(np.prod(self.size))


@dataclass
class Link:
    name: str
    mass: float
    boxes: list[Box] = field(default_factory=list)
    mesh: np.ndarray | None = None  # (k, 3) vertices in the link frame
    com: np.ndarray | None = None  # link-frame centre of mass (default: geometry centre)

    def vertices(self) -> np.ndarray:
        parts = [b.vertices() for b in self.boxes]
        if self.mesh is not None:
            parts.append(self.mesh)
        return np.concatenate(parts) if parts else np.empty((0, 3))

    def centre_of_mass(self) -> np.ndarray:
        if self.com is not None:
            return np.asarray(self.com, dtype=float)
        if self.boxes:
            w = np.array([b.volume for b in self.boxes])
            return (w[:, None] * np.array([b.center for b in self.boxes])).sum(0) / w.sum()
        return self.vertices().mean(axis=0)


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str
    child: str
    origin: tuple[float, float, float]
    axis: tuple[float, float, float]
    lower: float  # radians
    upper: float
    home: float


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation matrix about a unit ``axis``."""
    x, y, z = axis
    c, s = np.cos(angle), np.sin(angle)
    C = 1.0 - c
    return np.array(
        [
            [c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C],
        ]
    )


class Robot:
    """A tree of links on revolute joints; ``geometry(theta)`` is what the stability function needs."""

    def __init__(self, name: str, links: list[Link], joints: list[Joint]):
        self.name = name
        self.description = ""
        self.slope = 0.0
        self.links = {link.name: link for link in links}
        if len(self.links) != len(links):
            raise RobotFileError("link.name: two links share a name; give each link a unique name")
        children = {j.child for j in joints}
        roots = [link.name for link in links if link.name not in children]
        if len(roots) != 1:
            raise RobotFileError(
                f"joint: expected exactly one base link (a link that is no joint's child), got {roots}"
            )
        self.base = roots[0]
        order, placed, pending = [], {self.base}, list(joints)
        while pending:  # topological order: parents before children
            ready = [j for j in pending if j.parent in placed]
            if not ready:
                raise RobotFileError(
                    f"joint.parent: {pending[0].name!r} hangs off {pending[0].parent!r}, "
                    "which is not reachable from the base link"
                )
            for j in ready:
                order.append(j)
                placed.add(j.child)
                pending.remove(j)
        self.all_joints = order
        self.joints = order  # the active joints, the coordinates of θ
        self.locked: dict[str, float] = {}
        self.planar_override: bool | None = None
        self.mass = float(sum(link.mass for link in links))
        if self.mass <= 0:
            raise RobotFileError("link.mass: the robot's total mass must be > 0")
        self.link_vertices = {n: link.vertices() for n, link in self.links.items()}
        self.link_coms = {n: link.centre_of_mass() for n, link in self.links.items()}

    @property
    def dof(self) -> int:
        return len(self.joints)

    @property
    def joint_bounds(self) -> np.ndarray:
        """(m, 2) joint ranges in radians."""
        return np.array([[j.lower, j.upper] for j in self.joints], dtype=float).reshape(-1, 2)

    @property
    def home(self) -> np.ndarray:
        return np.array([j.home for j in self.joints], dtype=float)

    @property
    def planar(self) -> bool:
        """All joints turn about the base's y axis: the robot moves in the x-z plane (Figure 5.2).

        A robot file's ``planar = false`` forces the 3-D treatment (rolling sideways included).
        """
        if self.planar_override is not None:
            return self.planar_override
        return all(abs(abs(j.axis[1]) - 1.0) < 1e-9 for j in self.all_joints)

    def lock(self, values: dict[str, float]) -> Robot:
        """A copy with the named joints held at ``values`` (radians); the others stay active.

        Joints already locked stay locked.  Used to study a manipulator with fewer active
        joints (Figure 5.6).
        """
        names = {j.name for j in self.all_joints}
        for name in values:
            if name not in names:
                raise InputError(f"lock: no joint named {name!r}; joints: {', '.join(sorted(names))}")
        new = copy.copy(self)
        new.locked = {**self.locked, **{k: float(v) for k, v in values.items()}}
        new.joints = [j for j in self.all_joints if j.name not in new.locked]
        return new

    def joint_angles(self, theta: np.ndarray) -> np.ndarray:
        """Angles (..., len(all_joints)) of every joint in :attr:`all_joints` order: the active ones
        from joint states ``theta`` (..., dof), the locked ones at their held values."""
        theta = np.asarray(theta, dtype=float)
        out = np.empty(theta.shape[:-1] + (len(self.all_joints),))
        active = iter(range(self.dof))
        for k, j in enumerate(self.all_joints):
            out[..., k] = self.locked[j.name] if j.name in self.locked else theta[..., next(active)]
        return out

    def geometry(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Vertices (k, 3) and centre of mass (3,) in the base frame for joint state ``theta``."""
        theta = np.asarray(theta, dtype=float).reshape(-1)
        if theta.size != self.dof:
            raise InputError(f"theta: expected {self.dof} joint angles, got {theta.size}")
        R = {self.base: np.eye(3)}
        t = {self.base: np.zeros(3)}
        for j, angle in zip(self.all_joints, self.joint_angles(theta)):
            Rp, tp = R[j.parent], t[j.parent]
            R[j.child] = Rp @ rotation(np.asarray(j.axis), angle)
            t[j.child] = tp + Rp @ np.asarray(j.origin)
        verts, com = [], np.zeros(3)
        for n, link in self.links.items():
            verts.append(self.link_vertices[n] @ R[n].T + t[n])
            com += link.mass * (R[n] @ self.link_coms[n] + t[n])
        return np.concatenate(verts), com / self.mass

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, dof={self.dof}, links={len(self.links)}, mass={self.mass:g})"
