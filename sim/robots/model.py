"""Rigid-body robot models for self-righting analysis (chapter 5): links on revolute joints.

A robot is a tree of links rooted at the base (the body whose orientation is the "body
angle").  Each link carries collision geometry — boxes and optionally STL meshes — and a
mass; only the vertices matter, because a robot on a plane can touch the ground only with
points on its convex hull.  Forward kinematics gives every vertex and the centre of mass in
the base frame for a joint state θ.

Robots are read from a small TOML file (see ``examples/robots/*.toml``)::

    name = "1dof"
    [[link]]
    name = "body"
    mass = 10.0
    boxes = [{ size = [0.6, 0.4, 0.2], center = [0, 0, 0] }]
    [[link]]
    name = "arm"
    mass = 0.0
    boxes = [{ size = [0.5, 0.04, 0.04], center = [0.25, 0, 0] }]
    [[joint]]
    name = "shoulder"
    parent = "body"
    child = "arm"
    origin = [-0.25, 0, 0.1]   # joint position in the parent frame, metres
    axis = [0, 1, 0]           # rotation axis in the parent frame
    range = [-180, 180]        # degrees
    home = 0                   # degrees; the upright home state uses these

A link's mass is spread over its boxes by volume (a mesh link takes ``com``, default the
mean of its vertices).  A bad file raises :class:`RobotFileError` naming the field.
``load_robot`` also reads a URDF subset (``.urdf``, :mod:`sim.robots.urdf`) into the same
model, through the same validation (:func:`parse_parts`).
"""

from __future__ import annotations

import copy
import struct
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np

from rapt.errors import FileFormatError, InputError

__all__ = ["RobotFileError", "Box", "Link", "Joint", "Robot", "load_robot", "read_stl"]


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


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
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
        self._verts = {n: link.vertices() for n, link in self.links.items()}
        self._com = {n: link.centre_of_mass() for n, link in self.links.items()}

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
            R[j.child] = Rp @ _rotation(np.asarray(j.axis), angle)
            t[j.child] = tp + Rp @ np.asarray(j.origin)
        verts, com = [], np.zeros(3)
        for n, link in self.links.items():
            verts.append(self._verts[n] @ R[n].T + t[n])
            com += link.mass * (R[n] @ self._com[n] + t[n])
        return np.concatenate(verts), com / self.mass

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, dof={self.dof}, links={len(self.links)}, mass={self.mass:g})"


# -- TOML loading ----------------------------------------------------------------------------
@overload
def _vec(value: Any, where: str, n: Literal[3] = 3, positive: bool = False) -> tuple[float, float, float]: ...
@overload
def _vec(value: Any, where: str, n: Literal[2], positive: bool = False) -> tuple[float, float]: ...
def _vec(value: Any, where: str, n: int = 3, positive: bool = False) -> tuple[float, ...]:
    """``n`` finite numbers (positive ones if asked) from a TOML or URDF value; :class:`RobotFileError` otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.array([])
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
        kind = "positive numbers" if positive else "numbers"
        raise RobotFileError(f"{where}: expected {n} {kind}, got {value!r}")
    return tuple(float(v) for v in arr)


def _number(value: Any, where: str, minimum: float | None = None) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not np.isfinite(value)
        or (minimum is not None and value < minimum)
    ):
        bound = "" if minimum is None else f" >= {minimum:g}"
        raise RobotFileError(f"{where}: expected a number{bound}, got {value!r}")
    return float(value)


def _link(spec: Any, at: Callable[[str], str], folder: Path) -> Link:
    """A link from a TOML-shaped table; ``at(field)`` names a field in error messages (TOML or URDF spelling)."""
    if not isinstance(spec, dict):
        raise RobotFileError(f"{at('')}: expected a table with name, mass and boxes")
    unknown = set(spec) - {"name", "mass", "boxes", "mesh", "mesh_scale", "com"}
    if unknown:
        raise RobotFileError(
            f"{at(sorted(unknown)[0])}: unknown field; allowed: name, mass, boxes, mesh, mesh_scale, com"
        )
    name = spec.get("name")
    if not isinstance(name, str) or not name:
        raise RobotFileError(f"{at('name')}: expected a non-empty string, got {name!r}")
    mass = _number(spec.get("mass"), at("mass"), 0.0)
    boxes = []
    raw = spec.get("boxes", [])
    if not isinstance(raw, list):
        raise RobotFileError(f"{at('boxes')}: expected a list of {{size, center}} tables")
    for b, box in enumerate(raw):
        if not isinstance(box, dict) or "size" not in box:
            raise RobotFileError(f"{at(f'boxes[{b}]')}: expected a table with size = [x, y, z] (metres)")
        boxes.append(
            Box(
                _vec(box["size"], at(f"boxes[{b}].size"), positive=True),
                _vec(box.get("center", [0, 0, 0]), at(f"boxes[{b}].center")),
            )
        )
    mesh = None
    if "mesh" in spec:
        path = folder / str(spec["mesh"])
        if not path.is_file():
            raise RobotFileError(f"{at('mesh')}: {path} does not exist; give an STL path relative to the robot file")
        mesh = read_stl(path) * _number(spec.get("mesh_scale", 1.0), at("mesh_scale"), 0.0)
    if not boxes and mesh is None:
        raise RobotFileError(f"{at('boxes')}: link {name!r} has no geometry; give boxes or a mesh")
    com = None if "com" not in spec else np.asarray(_vec(spec["com"], at("com")))
    return Link(name, mass, boxes, mesh, com)


def _joint(spec: Any, at: Callable[[str], str]) -> Joint:
    """A joint from a TOML-shaped table (range and home in degrees); ``at`` as for :func:`_link`."""
    if not isinstance(spec, dict):
        raise RobotFileError(f"{at('')}: expected a table with name, parent, child, origin, axis, range")
    unknown = set(spec) - {"name", "parent", "child", "origin", "axis", "range", "home"}
    if unknown:
        raise RobotFileError(
            f"{at(sorted(unknown)[0])}: unknown field; allowed: name, parent, child, origin, axis, range, home"
        )
    for key in ("name", "parent", "child"):
        if not isinstance(spec.get(key), str) or not spec[key]:
            raise RobotFileError(f"{at(key)}: expected a link name (string), got {spec.get(key)!r}")
    axis = np.asarray(_vec(spec.get("axis"), at("axis")))
    if np.linalg.norm(axis) < 1e-12:
        raise RobotFileError(f"{at('axis')}: expected a non-zero vector, got {spec.get('axis')!r}")
    lo, hi = _vec(spec.get("range", [-180, 180]), at("range"), 2)
    if not (-360 <= lo < hi <= 360):
        raise RobotFileError(
            f"{at('range')}: expected [lower, upper] degrees with lower < upper within ±360, got {spec.get('range')!r}"
        )
    home = _number(spec.get("home", 0.0), at("home"))
    if not lo <= home <= hi:
        raise RobotFileError(f"{at('home')}: {home:g} lies outside range [{lo:g}, {hi:g}]")
    return Joint(
        spec["name"],
        spec["parent"],
        spec["child"],
        _vec(spec.get("origin", [0, 0, 0]), at("origin")),
        tuple(axis / np.linalg.norm(axis)),
        np.radians(lo),
        np.radians(hi),
        np.radians(home),
    )


def _toml_at(table: str, i: int) -> Callable[[str], str]:
    """TOML spelling of a field in error messages: ``link[0].boxes[1].size``."""
    return lambda key: f"{table}[{i}]" + (f".{key}" if key else "")


def parse_parts(
    link_specs: list,
    joint_specs: list,
    folder: Path,
    link_at: Callable[[int], Callable[[str], str]],
    joint_at: Callable[[int], Callable[[str], str]],
) -> tuple[list[Link], list[Joint]]:
    """Links and joints from TOML-shaped tables, validated, every joint's parent and child a known link.

    Shared by the TOML and URDF readers (:mod:`sim.robots.urdf`); ``link_at(i)`` and
    ``joint_at(i)`` give the field naming of the i-th table in error messages.
    """
    links = [_link(s, link_at(i), folder) for i, s in enumerate(link_specs)]
    joints = [_joint(s, joint_at(i)) for i, s in enumerate(joint_specs)]
    names = {link.name for link in links}
    for i, j in enumerate(joints):
        for key in ("parent", "child"):
            if getattr(j, key) not in names:
                raise RobotFileError(
                    f"{joint_at(i)(key)}: no link named {getattr(j, key)!r}; links: {', '.join(sorted(names))}"
                )
    return links, joints


def load_robot(path: str | Path) -> Robot:
    """Read a robot file, TOML or (by its ``.urdf`` suffix) URDF; :class:`RobotFileError` names the offending field."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".urdf":
        from sim.robots.urdf import load_urdf

        return load_urdf(path)
    if suffix != ".toml":
        raise RobotFileError(f"ROBOT_FILE: {path} is neither .toml nor .urdf; give a robot TOML or URDF file")
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise RobotFileError(f"ROBOT_FILE: {path} does not exist; give a robot TOML file") from None
    except tomllib.TOMLDecodeError as exc:
        raise RobotFileError(f"ROBOT_FILE: {path} is not valid TOML ({exc})") from None
    unknown = set(data) - {"name", "description", "link", "joint", "slope", "planar"}
    if unknown:
        raise RobotFileError(
            f"{sorted(unknown)[0]}: unknown top-level field; allowed: name, description, link, joint, slope, planar"
        )
    links = data.get("link")
    if not isinstance(links, list) or not links:
        raise RobotFileError("link: expected at least one [[link]] table")
    joints = data.get("joint", [])
    if not isinstance(joints, list):
        raise RobotFileError("joint: expected [[joint]] tables")
    parsed_links, parsed_joints = parse_parts(
        links, joints, path.parent, lambda i: _toml_at("link", i), lambda i: _toml_at("joint", i)
    )
    robot = Robot(str(data.get("name", path.stem)), parsed_links, parsed_joints)
    robot.description = str(data.get("description", ""))
    robot.slope = _number(data.get("slope", 0.0), "slope", 0.0)  # degrees, the default ground slope
    if "planar" in data:
        if not isinstance(data["planar"], bool):
            raise RobotFileError(f"planar: expected true or false, got {data['planar']!r}")
        robot.planar_override = data["planar"]
    if robot.slope >= 90:
        raise RobotFileError(f"slope: expected degrees in [0, 90), got {robot.slope:g}")
    return robot


def read_stl(path: str | Path) -> np.ndarray:
    """Unique vertices (k, 3) of an ASCII or binary STL file."""
    raw = Path(path).read_bytes()
    if raw[:5].lower() == b"solid" and b"facet" in raw[:2048]:
        pts = [
            list(map(float, line.split()[1:4]))
            for line in raw.decode(errors="replace").splitlines()
            if line.strip().startswith("vertex")
        ]
        verts = np.asarray(pts, dtype=float).reshape(-1, 3)
    else:
        (n,) = struct.unpack("<I", raw[80:84])
        rec = np.frombuffer(
            raw, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]), count=n, offset=84
        )
        verts = rec["v"].reshape(-1, 3).astype(float)
    if verts.size == 0:
        raise RobotFileError(f"mesh: {path} holds no triangles")
    return np.unique(verts, axis=0)
