"""Ground robots for self-righting studies (chapter 5): rigid-link models and their stability function.

``load_robot(path)`` reads a robot TOML file (or a URDF subset, ``.urdf``); ``StabilityFunction(robot, slope_deg)`` is
Algorithm 5: hull faces as body angles, snapping a queried body angle to the nearest face,
quasi-static tipping until a stable face is reached, and the potential energy lost.
"""

from sim.robots.model import Box, Joint, Link, Robot, RobotFileError
from sim.robots.parts import read_stl
from sim.robots.robotfile import load_robot
from sim.robots.stability import Hull, StabilityFunction, StabilityResult, body_angles, down_normals
from sim.robots.tipping import GRAVITY

__all__ = [
    "Box",
    "Joint",
    "Link",
    "Robot",
    "RobotFileError",
    "load_robot",
    "read_stl",
    "GRAVITY",
    "Hull",
    "StabilityFunction",
    "StabilityResult",
    "body_angles",
    "down_normals",
]
