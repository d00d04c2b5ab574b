"""Robot files: a robot read from a small TOML file, or from a URDF subset (:mod:`sim.robots.urdf`).

A TOML robot file (see ``examples/robots/*.toml``)::

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
mean of its vertices).  A bad file raises :class:`~sim.robots.model.RobotFileError` naming the
field.  Links and joints go through the validation both formats share
(:func:`sim.robots.parts.parse_parts`).
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path

from sim.robots.model import Robot, RobotFileError
from sim.robots.parts import number, parse_parts
from sim.robots.urdf import load_urdf

__all__ = ["load_robot"]


def _toml_at(table: str, i: int) -> Callable[[str], str]:
    """TOML spelling of a field in error messages: ``link[0].boxes[1].size``."""
    return lambda key: f"{table}[{i}]" + (f".{key}" if key else "")


def load_robot(path: str | Path) -> Robot:
    """Read a robot file, TOML or (by its ``.urdf`` suffix) URDF; :class:`RobotFileError` names the offending field."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".urdf":
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
    robot.slope = number(data.get("slope", 0.0), "slope", 0.0)  # degrees, the default ground slope
    if "planar" in data:
        if not isinstance(data["planar"], bool):
            raise RobotFileError(f"planar: expected true or false, got {data['planar']!r}")
        robot.planar_override = data["planar"]
    if robot.slope >= 90:
        raise RobotFileError(f"slope: expected degrees in [0, 90), got {robot.slope:g}")
    return robot
