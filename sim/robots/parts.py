"""Robot parts from robot-file tables: validated links and joints, and the STL meshes links use.

Both robot file formats (TOML, :mod:`sim.robots.robotfile`; the URDF subset,
:mod:`sim.robots.urdf`) turn their file into TOML-shaped tables and hand them to
:func:`parse_parts`, so both accept and reject the same values; a bad value raises
:class:`~sim.robots.model.RobotFileError` naming the field in the file's own spelling.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np

from sim.robots.model import Box, Joint, Link, RobotFileError

__all__ = ["number", "parse_parts", "read_stl", "vector"]


@overload
def vector(value: Any, where: str, n: Literal[3] = 3, positive: bool = False) -> tuple[float, float, float]: ...
@overload
def vector(value: Any, where: str, n: Literal[2], positive: bool = False) -> tuple[float, float]: ...
def vector(value: Any, where: str, n: int = 3, positive: bool = False) -> tuple[float, ...]:
    """``n`` finite numbers (positive ones if asked) from a TOML or URDF value; :class:`RobotFileError` otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        arr = np.array([])
    if arr.shape != (n,) or not np.all(np.isfinite(arr)) or (positive and np.any(arr <= 0)):
        kind = "positive numbers" if positive else "numbers"
        raise RobotFileError(f"{where}: expected {n} {kind}, got {value!r}")
    return tuple(float(v) for v in arr)


def number(value: Any, where: str, minimum: float | None = None) -> float:
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
    mass = number(spec.get("mass"), at("mass"), 0.0)
    boxes = []
    raw = spec.get("boxes", [])
    if not isinstance(raw, list):
        raise RobotFileError(f"{at('boxes')}: expected a list of {{size, center}} tables")
    for b, box in enumerate(raw):
        if not isinstance(box, dict) or "size" not in box:
            raise RobotFileError(f"{at(f'boxes[{b}]')}: expected a table with size = [x, y, z] (metres)")
        boxes.append(
            Box(
                vector(box["size"], at(f"boxes[{b}].size"), positive=True),
                vector(box.get("center", [0, 0, 0]), at(f"boxes[{b}].center")),
            )
        )
    mesh = None
    if "mesh" in spec:
        path = folder / str(spec["mesh"])
        if not path.is_file():
            raise RobotFileError(f"{at('mesh')}: {path} does not exist; give an STL path relative to the robot file")
        mesh = read_stl(path) * number(spec.get("mesh_scale", 1.0), at("mesh_scale"), 0.0)
    if not boxes and mesh is None:
        raise RobotFileError(f"{at('boxes')}: link {name!r} has no geometry; give boxes or a mesh")
    com = None if "com" not in spec else np.asarray(vector(spec["com"], at("com")))
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
    axis = np.asarray(vector(spec.get("axis"), at("axis")))
    if np.linalg.norm(axis) < 1e-12:
        raise RobotFileError(f"{at('axis')}: expected a non-zero vector, got {spec.get('axis')!r}")
    lo, hi = vector(spec.get("range", [-180, 180]), at("range"), 2)
    if not (-360 <= lo < hi <= 360):
        raise RobotFileError(
            f"{at('range')}: expected [lower, upper] degrees with lower < upper within ±360, got {spec.get('range')!r}"
        )
    home = number(spec.get("home", 0.0), at("home"))
    if not lo <= home <= hi:
        raise RobotFileError(f"{at('home')}: {home:g} lies outside range [{lo:g}, {hi:g}]")
    return Joint(
        spec["name"],
        spec["parent"],
        spec["child"],
        vector(spec.get("origin", [0, 0, 0]), at("origin")),
        tuple(axis / np.linalg.norm(axis)),
        np.radians(lo),
        np.radians(hi),
        np.radians(home),
    )


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
