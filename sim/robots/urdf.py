"""A URDF subset for self-righting robots: the same :class:`~sim.robots.model.Robot` as a TOML file.

Read with :mod:`xml.etree`; what a self-righting study needs, nothing more:

* ``<link name>``: ``<inertial><mass value>`` (kg) and ``<inertial><origin xyz>`` (the
  centre of mass, default the link origin); a link without ``<inertial>`` is massless, as
  in URDF.  Collision geometry: ``<collision><geometry><box size>`` placed by
  ``<collision><origin xyz>``, and at most one STL ``<mesh filename [scale]>`` (a path
  relative to the URDF file or ``file://``; a uniform scale).  ``<visual>`` is ignored.
* ``<joint type>``: ``revolute`` (``<limit lower upper>`` in radians, required),
  ``continuous`` (a full turn) or ``fixed`` (kept as a joint locked at 0, so it adds no
  coordinate); ``<parent link>``, ``<child link>``, ``<origin xyz>``, ``<axis xyz>``
  (default ``1 0 0``).  The home state is 0 for every joint (clipped into its limits).
* Rotated frames (a non-zero ``rpy`` on a joint or collision origin), other joint types,
  ``<mimic>`` joints and other geometry (cylinders, spheres) raise
  :class:`~sim.robots.model.RobotFileError` naming the element by its XPath, e.g.
  ``joint[@name='shoulder']/origin/@rpy``.  URDF has no ground, so the robot's default
  slope is 0.

The tables built here go through the TOML reader's own validation
(:func:`sim.robots.parts.parse_parts`), so both formats accept and reject the same values.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import numpy as np

from sim.robots.model import Robot, RobotFileError
from sim.robots.parts import parse_parts, vector

__all__ = ["load_urdf"]

_JOINT_TYPES = ("revolute", "continuous", "fixed")


def _numbers(el: ET.Element | None, attr: str, default: str) -> list[float] | str:
    """An attribute's space-separated numbers; the raw text when one is not a number (the validator reports it)."""
    raw = None if el is None else el.get(attr)
    text = default if raw is None else raw
    try:
        return [float(t) for t in text.split()]
    except ValueError:
        return text


def _no_rotation(origin: ET.Element | None, where: str) -> None:
    if origin is None:  # no <origin>: rpy is 0 0 0
        return
    rpy = _numbers(origin, "rpy", "0 0 0")
    if isinstance(rpy, str) or len(rpy) != 3 or any(abs(v) > 1e-12 for v in rpy):
        raise RobotFileError(
            f"{where}/origin/@rpy: rotated frames are not supported, got {origin.get('rpy')!r}; "
            'use rpy="0 0 0" and give the geometry or axis in the parent\'s orientation'
        )


def _child_attr(el: ET.Element, tag: str, attr: str) -> str | None:
    child = el.find(tag)
    return None if child is None else child.get(attr)


def _element_name(el: ET.Element, i: int) -> str:
    """XPath of a top-level link or joint: by name, else by position (1-based, as XPath counts)."""
    name = el.get("name")
    return f"{el.tag}[@name='{name}']" if name else f"{el.tag}[{i + 1}]"


def _link_table(el: ET.Element, where: str) -> tuple[dict, Callable[[str], str], np.ndarray]:
    """A TOML-shaped link table, its field naming in URDF terms, and the mesh offset (collision origin)."""
    spec: dict = {"name": el.get("name")}
    inertial = el.find("inertial")
    if inertial is None:
        spec["mass"] = 0.0
    else:
        mass = inertial.find("mass")
        if mass is None or mass.get("value") is None:
            raise RobotFileError(
                f'{where}/inertial/mass/@value: missing; give <mass value="KG"/> (value="0" for a massless link)'
            )
        value = _numbers(mass, "value", "")
        spec["mass"] = value[0] if isinstance(value, list) and len(value) == 1 else mass.get("value")
        # the inertial origin's rpy only orients the inertia tensor, which a quasi-static study does not use
        spec["com"] = _numbers(inertial.find("origin"), "xyz", "0 0 0")
    boxes, box_at, mesh_at, offset = [], [], None, np.zeros(3)
    for k, col in enumerate(el.findall("collision"), start=1):
        at = f"{where}/collision[{k}]"
        origin = col.find("origin")
        _no_rotation(origin, at)
        xyz = _numbers(origin, "xyz", "0 0 0")
        geometry = col.find("geometry")
        shapes = [] if geometry is None else list(geometry)
        if len(shapes) != 1:
            raise RobotFileError(
                f"{at}/geometry: expected exactly one <box> or <mesh>, got {[s.tag for s in shapes] or 'none'}"
            )
        shape = shapes[0]
        if shape.tag == "box":
            boxes.append({"size": _numbers(shape, "size", ""), "center": xyz})
            box_at.append(at)
        elif shape.tag == "mesh":
            if mesh_at is not None:
                raise RobotFileError(
                    f"{at}/geometry/mesh: a link may have one mesh ({mesh_at} is the first); "
                    "merge the STL files or split the link"
                )
            mesh_at = at
            filename = shape.get("filename") or ""
            if filename.startswith("file://"):
                filename = filename[len("file://") :]
            if "://" in filename or not filename.lower().endswith(".stl"):
                raise RobotFileError(
                    f"{at}/geometry/mesh/@filename: expected an STL file path relative to the URDF "
                    f"(or file://), got {shape.get('filename')!r}; package:// needs ROS, convert other "
                    "formats to STL"
                )
            scale = _numbers(shape, "scale", "1 1 1")
            if isinstance(scale, str) or len(scale) != 3 or len(set(scale)) != 1:
                raise RobotFileError(
                    f"{at}/geometry/mesh/@scale: expected one factor for all three axes, got {shape.get('scale')!r}"
                )
            spec["mesh"], spec["mesh_scale"] = filename, scale[0]
            offset = np.asarray(vector(xyz, f"{at}/origin/@xyz"))
        else:
            raise RobotFileError(f"{at}/geometry/{shape.tag}: not supported; use <box> (or an STL <mesh>) instead")
    if boxes:
        spec["boxes"] = boxes
    fields = {
        "": "",
        "name": "/@name",
        "mass": "/inertial/mass/@value",
        "com": "/inertial/origin/@xyz",
        "boxes": "/collision",
        "mesh": "/geometry/mesh/@filename",
        "mesh_scale": "/geometry/mesh/@scale",
    }

    def field_at(key: str) -> str:
        if key.startswith("boxes["):
            b, _, part = key[len("boxes[") :].partition("]")
            return box_at[int(b)] + ("/origin/@xyz" if part == ".center" else "/geometry/box/@size")
        if key.startswith("mesh"):
            return f"{mesh_at}{fields[key]}"
        return where + fields.get(key, "/" + key)

    return spec, field_at, offset


def _joint_table(el: ET.Element, where: str) -> tuple[dict, Callable[[str], str]]:
    """A TOML-shaped joint table (degrees) and its field naming in URDF terms."""
    kind = el.get("type")
    if kind not in _JOINT_TYPES:
        raise RobotFileError(f"{where}/@type: {kind!r} joints are not supported; use revolute, continuous or fixed")
    if el.find("mimic") is not None:
        raise RobotFileError(
            f"{where}/mimic: coupled joints are not supported; remove <mimic> to make the joint independent"
        )
    origin = el.find("origin")
    _no_rotation(origin, where)
    spec: dict[str, object] = {
        "name": el.get("name"),
        "parent": _child_attr(el, "parent", "link"),
        "child": _child_attr(el, "child", "link"),
        "origin": _numbers(origin, "xyz", "0 0 0"),
        "axis": _numbers(el.find("axis"), "xyz", "1 0 0"),
    }
    if kind == "revolute":
        limit = el.find("limit")
        if limit is None or limit.get("lower") is None or limit.get("upper") is None:
            raise RobotFileError(
                f'{where}/limit: a revolute joint needs <limit lower="RAD" upper="RAD"/>; '
                'use type="continuous" for a full turn'
            )
        lower, upper = _numbers(limit, "lower", ""), _numbers(limit, "upper", "")
        if isinstance(lower, list) and isinstance(upper, list) and len(lower) == len(upper) == 1:
            lo, hi = float(np.degrees(lower[0])), float(np.degrees(upper[0]))
            spec["range"] = [lo, hi]
            spec["home"] = float(np.clip(0.0, min(lo, hi), max(lo, hi)))  # URDF has no home state
        else:
            spec["range"] = f"{limit.get('lower')} {limit.get('upper')}"  # the validator names it
    else:
        spec["range"] = [-180.0, 180.0]
        if kind == "fixed":  # locked at 0, so its axis never turns anything; y keeps a planar robot planar
            spec["axis"] = [0.0, 1.0, 0.0]
    fields = {
        "": "",
        "name": "/@name",
        "parent": "/parent/@link",
        "child": "/child/@link",
        "origin": "/origin/@xyz",
        "axis": "/axis/@xyz",
        "range": "/limit/@lower and @upper (radians, shown in degrees)",
        "home": "",
    }
    return spec, lambda key: where + fields.get(key, "/" + key)


def load_urdf(path: str | Path) -> Robot:
    """Read a robot from the URDF subset above; :class:`RobotFileError` names the element and attribute."""
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except FileNotFoundError:
        raise RobotFileError(f"ROBOT_FILE: {path} does not exist; give a robot URDF file") from None
    except ET.ParseError as exc:
        raise RobotFileError(f"ROBOT_FILE: {path} is not valid XML ({exc})") from None
    if root.tag != "robot":
        raise RobotFileError(f"{root.tag}: expected a <robot> root element (URDF)")
    link_els, joint_els = root.findall("link"), root.findall("joint")
    if not link_els:
        raise RobotFileError("robot/link: expected at least one <link>")
    links = [_link_table(el, _element_name(el, i)) for i, el in enumerate(link_els)]
    joints = [_joint_table(el, _element_name(el, i)) for i, el in enumerate(joint_els)]
    parsed_links, parsed_joints = parse_parts(
        [t[0] for t in links], [t[0] for t in joints], path.parent, lambda i: links[i][1], lambda i: joints[i][1]
    )
    for link, (_, _, offset) in zip(parsed_links, links):
        if link.mesh is not None:
            link.mesh = link.mesh + offset
    robot = Robot(root.get("name") or path.stem, parsed_links, parsed_joints)
    # parse_parts kept the joints in file order and checked every name
    fixed = {joint.name: 0.0 for joint, el in zip(parsed_joints, joint_els) if el.get("type") == "fixed"}
    return robot.lock(fixed) if fixed else robot
