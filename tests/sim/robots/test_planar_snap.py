"""The hull-free planar snap (the PRM's path checks) against Algorithm 5, and the 5-DOF robot's elbow convention."""

from __future__ import annotations

import numpy as np
import pytest

from sim.robots import StabilityFunction, load_robot
from sim.robots.planar import planar_snap


@pytest.mark.parametrize("name, slope", [("1dof", 20.0), ("2dof", 0.0), ("3dof", 0.0)])
def test_planar_snap_gives_the_stability_function_s_face_and_label(name, slope):
    """Random states, and states lying exactly on a face (where two extreme vertices tie), special joint angles too."""
    robot = load_robot(f"examples/robots/{name}.toml")
    F = StabilityFunction(robot, slope)
    rng = np.random.default_rng(5)
    theta = robot.joint_bounds[:, 0] + rng.random((300, robot.dof)) * np.ptp(robot.joint_bounds, axis=1)
    theta[:60] = np.radians(np.round(np.degrees(theta[:60]) / 45) * 45)
    phi = rng.uniform(-np.pi, np.pi, len(theta))
    on_face = F.all_faces(theta[:40])  # every face of 40 joint states, queried at its own body angle
    theta = np.concatenate([theta, on_face.theta])
    phi = np.concatenate([phi, on_face.start[:, 0]])
    want = F(theta, phi[:, None])
    start, stable, ids = planar_snap(F, theta, phi)
    assert np.abs(np.angle(np.exp(1j * (start - want.start[:, 0])))).max() < 1e-9
    assert np.array_equal(stable, want.stable)
    assert np.array_equal(ids, want.start_id)
    # a face queried at its own body angle snaps onto itself
    n = len(on_face)
    assert np.array_equal(ids[-n:], on_face.start_id) and np.array_equal(stable[-n:], on_face.stable)


def test_five_dof_elbow_runs_from_folded_to_full_extension_at_180_degrees():
    """Section 5.5.2: the elbow is "locked at full extension (180 degrees)"; it folds up over the upper arm."""
    robot = load_robot("examples/robots/5dof.toml")
    elbow = next(j for j in robot.all_joints if j.name == "elbow")
    assert np.degrees([elbow.lower, elbow.upper, elbow.home]).tolist() == pytest.approx([0.0, 180.0, 180.0])
    arm = {"shoulder_yaw": 0.0, "shoulder_pitch": 0.0, "wrist": 0.0, "jaw": 0.0}

    def reach(deg):  # the jaw's far end in the base frame, the arm pointing forward
        verts, _ = robot.lock({**arm, "elbow": np.radians(deg)}).geometry(np.zeros(0))
        return verts[-8:].mean(axis=0)

    straight, right_angle, folded = reach(180.0), reach(90.0), reach(0.0)
    shoulder_x, length = 0.18, 0.50 + 0.45 + 0.08 + 0.06  # turret, upper arm, forearm, wrist, jaw centre
    assert straight[0] == pytest.approx(shoulder_x + length, abs=0.02)
    assert right_angle[2] > straight[2] + 0.4  # the forearm stands up above the upper arm
    assert folded[0] < shoulder_x + 0.1  # folded back along the upper arm
