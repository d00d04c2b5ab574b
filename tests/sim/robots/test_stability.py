"""Algorithm 5 on shapes with known answers: hull faces, snapping, tipping angles, energies, robot files."""

from __future__ import annotations

import numpy as np
import pytest

from sim.robots import Box, Link, Robot, RobotFileError, StabilityFunction, body_angles, down_normals, load_robot
from sim.robots.parts import read_stl

L, W, H, M = 0.4, 0.3, 0.2, 2.0  # box length (x), width (y), height (z), mass
NO_JOINTS = np.zeros((1, 0))


def box_robot() -> Robot:
    return Robot("box", [Link("b", M, [Box((L, W, H))])], [])


@pytest.mark.parametrize("planar", [True, False])
def test_box_hull_faces_are_its_sides(planar):
    F = StabilityFunction(box_robot(), 0.0, planar=planar)
    hull = F.hull(np.zeros(0))
    assert hull.n_faces == (4 if planar else 6)  # coplanar triangles merged into one face each
    got = {tuple(np.round(n, 9) + 0.0) for n in hull.normals}
    sides = {(0.0, 0.0, -1.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)}
    assert sides <= got
    # body angles round-trip to the face normals
    assert np.allclose(down_normals(hull.angles, F.planar), hull.normals, atol=1e-12)
    if planar:
        assert sorted(np.round(np.degrees(hull.angles[:, 0])) % 360) == [0, 90, 180, 270]


@pytest.mark.parametrize("planar", [True, False])
def test_box_on_slope_tips_at_the_analytic_angle(planar):
    """Lying on its long face a box tips when tan(slope) > L/H; standing on its end when > H/L."""
    lying, standing = np.degrees(np.arctan(L / H)), np.degrees(np.arctan(H / L))  # 63.43°, 26.57°
    flat = np.zeros((1, 1 if planar else 2))
    on_end = np.array([[np.pi / 2]]) if planar else np.array([[0.0, np.pi / 2]])
    for slope, lying_ok, standing_ok in [
        (lying - 0.3, True, False),
        (lying + 0.3, False, False),
        (standing - 0.3, True, True),
        (standing + 0.3, True, False),
    ]:
        F = StabilityFunction(box_robot(), slope, planar=planar)
        assert F(NO_JOINTS, flat).stable[0] == lying_ok, slope
        assert F(NO_JOINTS, on_end).stable[0] == standing_ok, slope


def test_box_standing_on_end_falls_downhill_and_loses_the_analytic_energy():
    slope = 30.0
    F = StabilityFunction(box_robot(), slope)
    res = F(NO_JOINTS, np.array([[np.pi / 2]]))
    assert not res.stable[0] and res.tips[0] == 1
    # it pivots on its downhill corner: the centre of mass goes from H/2 uphill of the corner and
    # L/2 above the ground to L/2 downhill of it and H/2 above the ground (ground frame x, z)
    s = np.radians(slope)
    up = np.array([-np.sin(s), np.cos(s)])  # world vertical in the ground frame (x downhill, z normal)
    before_rel = np.array([-H / 2, L / 2])
    after_rel = np.array([L / 2, H / 2])
    expected = M * 9.81 * (up @ before_rel - up @ after_rel)
    assert res.energy[0] == pytest.approx(expected, rel=1e-9)
    assert res.energy[0] > 0
    # it lands on a long face (pitch 0 or 180°): top face when it falls forward, nose downhill
    assert np.isclose(np.cos(res.rest[0, 0]), 1.0) or np.isclose(np.cos(res.rest[0, 0]), -1.0)


def test_box_rolls_away_when_no_face_is_stable():
    F = StabilityFunction(box_robot(), 70.0)
    res = F(NO_JOINTS, np.zeros((1, 1)))
    assert not res.stable[0] and np.isinf(res.energy[0]) and np.isnan(res.rest[0, 0])


def test_flat_ground_stability_is_independent_of_hull_representation():
    """A planar robot's 2-D hull (pitch) and 3-D hull (roll, pitch) agree state by state on flat ground."""
    robot = load_robot("examples/robots/1dof.toml")
    theta = np.radians(np.arange(-180, 180, 10.0))[:, None]
    a = StabilityFunction(robot, 0.0).all_faces(theta)
    b = StabilityFunction(robot, 0.0, planar=False).all_faces(theta)
    na, nb = down_normals(a.start, True), down_normals(b.start, False)
    ra, rb = down_normals(a.rest, True), down_normals(b.rest, False)
    for i in range(len(a)):
        j = np.flatnonzero((b.theta[:, 0] == a.theta[i, 0]) & (np.abs(nb - na[i]).max(axis=1) < 1e-6))
        assert len(j) == 1
        assert b.stable[j[0]] == a.stable[i]
        assert np.allclose(rb[j[0]], ra[i], atol=1e-6)
        assert b.energy[j[0]] == pytest.approx(a.energy[i], abs=1e-9)


@pytest.mark.parametrize("planar", [True, False])
def test_snapping_projects_a_query_onto_the_nearest_face(planar):
    F = StabilityFunction(box_robot(), 0.0, planar=planar)
    hull = F.hull(np.zeros(0))
    rng = np.random.default_rng(3)
    for _ in range(50):
        q = rng.uniform(-np.pi, np.pi, 1) if planar else np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5)])
        f = F.snap(hull, q)
        down = down_normals(q[None], planar)[0]
        assert hull.normals[f] @ down == pytest.approx((hull.normals @ down).max())
    # a query 40° nose-down snaps onto the bottom face, 50° onto the front face
    angle = lambda deg: np.radians([[deg]]) if planar else np.radians([[0.0, deg]])  # noqa: E731
    assert np.allclose(F(NO_JOINTS, angle(40)).start, angle(0)[0], atol=1e-12)
    assert np.allclose(F(NO_JOINTS, angle(50)).start, angle(90)[0], atol=1e-12)
    assert np.allclose(body_angles(down_normals(angle(50), planar), planar), angle(50))


def test_one_dof_robot_rights_itself_with_its_arm():
    """Upside down (pitch 180°) the robot is stable with its arm folded; swinging the arm tips it."""
    robot = load_robot("examples/robots/1dof.toml")
    F = StabilityFunction(robot, 0.0)
    upright = F(robot.home[None], np.zeros((1, 1)))
    assert upright.stable[0]
    folded = F(np.zeros((1, 1)), np.array([[np.pi]]))
    assert folded.stable[0]
    swing = np.radians(np.arange(-180, 180, 2.0))[:, None]
    res = F(swing, np.full((len(swing), 1), np.pi))
    assert (~res.stable).any() and res.stable.any()
    assert np.all(res.energy[~res.stable] > 0)
    assert np.all(res.energy[res.stable] == 0)


def test_robot_file_errors_name_the_field(tmp_path):
    good = tmp_path / "ok.toml"
    good.write_text('[[link]]\nname = "b"\nmass = 1\nboxes = [{ size = [1, 1, 1] }]\n')
    assert load_robot(good).dof == 0
    cases = {
        'name = "x"\n': "link:",
        '[[link]]\nname = "b"\nmass = -1\nboxes = [{ size = [1, 1, 1] }]\n': "link[0].mass",
        '[[link]]\nname = "b"\nmass = 1\nboxes = [{ size = [1, 0, 1] }]\n': "link[0].boxes[0].size",
        '[[link]]\nname = "b"\nmass = 1\nboxes = [{ size = [1, 1, 1] }]\n[[joint]]\nname = "j"\nparent = "b"\n'
        'child = "arm"\naxis = [0, 1, 0]\n': "joint[0].child",
        '[[link]]\nname = "b"\nmass = 1\nboxes = [{ size = [1, 1, 1] }]\n[[link]]\nname = "a"\nmass = 1\n'
        'boxes = [{ size = [1, 1, 1] }]\n[[joint]]\nname = "j"\nparent = "b"\nchild = "a"\naxis = [0, 0, 0]\n': "joint[0].axis",
        '[[link]]\nname = "b"\nmass = 1\nboxes = [{ size = [1, 1, 1] }]\nwheels = 4\n': "wheels",
    }
    for text, field in cases.items():
        bad = tmp_path / "bad.toml"
        bad.write_text(text)
        with pytest.raises(RobotFileError, match=field.replace("[", r"\[").replace("]", r"\]")):
            load_robot(bad)


def test_stl_mesh_link(tmp_path):
    """An ASCII STL tetrahedron is read as its 4 vertices and joins the hull."""
    tri = [
        ((0, 0, 0), (1, 0, 0), (0, 1, 0)),
        ((0, 0, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 0), (0, 1, 0), (0, 0, 1)),
        ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
    ]
    lines = (
        ["solid t"]
        + [
            "facet normal 0 0 0\nouter loop\n" + "".join(f"vertex {x} {y} {z}\n" for x, y, z in t) + "endloop\nendfacet"
            for t in tri
        ]
        + ["endsolid t"]
    )
    (tmp_path / "t.stl").write_text("\n".join(lines))
    assert read_stl(tmp_path / "t.stl").shape == (4, 3)
    (tmp_path / "r.toml").write_text('[[link]]\nname = "b"\nmass = 1\nmesh = "t.stl"\n')
    robot = load_robot(tmp_path / "r.toml")
    hull = StabilityFunction(robot, 0.0, planar=False).hull(np.zeros(0))
    assert hull.n_faces == 4


@pytest.mark.parametrize("name, slope", [("1dof", 20.0), ("2dof", 0.0), ("3dof", 0.0), ("2dof", 25.0)])
def test_bulk_planar_faces_equal_the_per_state_path(name, slope):
    """sim.robots.planar (the grid's bulk path) gives every face, label, resting face, energy and identity of the per-hull path."""
    from sim.robots.planar import planar_all_faces

    robot = load_robot(f"examples/robots/{name}.toml")
    F = StabilityFunction(robot, slope)
    rng = np.random.default_rng(7)
    theta = robot.joint_bounds[:, 0] + rng.random((40, robot.dof)) * np.ptp(robot.joint_bounds, axis=1)
    theta = np.unique(
        np.concatenate([theta, np.radians(np.round(np.degrees(theta) / 45) * 45)]), axis=0
    )  # special angles too
    bulk = planar_all_faces(F, theta, chunk=17)
    for i, th in enumerate(theta):
        hull = F.hull(th)
        rest, energy, tips = F.settle_all(hull)
        want = sorted(
            zip(
                np.round(hull.angles[:, 0], 9),
                tips == 0,
                np.round(np.where(np.isfinite(energy), energy, -1), 9),
                hull.ids,
                np.where(rest >= 0, hull.ids[np.maximum(rest, 0)], -1),
            )
        )
        m = bulk["row"] == i
        got = sorted(
            zip(
                np.round(bulk["start"][m], 9),
                bulk["stable"][m],
                np.round(np.where(np.isfinite(bulk["energy"][m]), bulk["energy"][m], -1), 9),
                bulk["start_id"][m],
                bulk["rest_id"][m],
            )
        )
        assert got == want, np.degrees(th)


def test_face_identities_name_a_face_across_joint_states():
    robot = load_robot("examples/robots/2dof.toml")
    F = StabilityFunction(robot, 0.0)
    a, b = F.hull(np.radians([30.0, -60.0])), F.hull(np.radians([30.5, -60.5]))
    assert len(set(a.ids.tolist())) == a.n_faces  # distinct faces, distinct names
    bottom = lambda h: h.ids[np.argmin(np.abs(h.angles[:, 0]))]  # noqa: E731  (the body's underside, pitch 0)
    assert bottom(a) == bottom(b)
    assert set(a.ids.tolist()) == set(b.ids.tolist())  # half a degree moves no vertex onto or off the hull here
    # a query reports the identities of its starting and resting faces
    res = F(np.radians([[30.0, -60.0]]), np.zeros((1, 1)))
    assert res.start_id[0] == bottom(a) and res.rest_id[0] == bottom(a) and res.stable[0]


def test_urdf_one_dof_robot_equals_the_toml_one():
    """examples/robots/1dof.urdf is 1dof.toml in URDF: same vertices, centre of mass, ranges and stability answers."""
    toml, urdf = load_robot("examples/robots/1dof.toml"), load_robot("examples/robots/1dof.urdf")
    assert (urdf.name, urdf.dof, urdf.mass, urdf.planar) == (toml.name, toml.dof, toml.mass, toml.planar)
    assert np.array_equal(urdf.joint_bounds, toml.joint_bounds) and np.array_equal(urdf.home, toml.home)
    theta = np.radians([[-180.0], [-97.5], [0.0], [33.0], [150.0]])
    for th in theta:
        (va, ca), (vb, cb) = toml.geometry(th), urdf.geometry(th)
        assert np.array_equal(va, vb) and np.array_equal(ca, cb)
    phi = np.radians([[180.0], [10.0], [0.0], [-90.0], [120.0]])
    a, b = StabilityFunction(toml, 20.0)(theta, phi), StabilityFunction(urdf, 20.0)(theta, phi)
    for key in ("start", "stable", "rest", "energy", "tips", "start_id", "rest_id"):
        assert np.array_equal(getattr(a, key), getattr(b, key), equal_nan=key != "stable"), key


_URDF = open("examples/robots/1dof.urdf").read()


@pytest.mark.parametrize(
    "old, new, where",
    [
        ('type="revolute"', 'type="prismatic"', "joint[@name='shoulder']/@type"),
        (
            '<origin xyz="-0.22 0 0.10" rpy="0 0 0"/>',
            '<origin xyz="-0.22 0 0.10" rpy="0 0.5 0"/>',
            "joint[@name='shoulder']/origin/@rpy",
        ),
        (
            '<origin xyz="0.275 0 0" rpy="0 0 0"/>',
            '<origin xyz="0.275 0 0" rpy="0.1 0 0"/>',
            "link[@name='arm']/collision[1]/origin/@rpy",
        ),
        ('<mass value="10.0"/>', "", "link[@name='body']/inertial/mass/@value"),
        ('<parent link="body"/>', '<parent link="bodyy"/>', "joint[@name='shoulder']/parent/@link"),
        (
            '<box size="0.60 0.40 0.20"/>',
            '<box size="0.60 -0.40 0.20"/>',
            "link[@name='body']/collision[1]/geometry/box/@size",
        ),
        (
            '<box size="0.55 0.06 0.04"/>',
            '<cylinder radius="0.03" length="0.55"/>',
            "link[@name='arm']/collision[1]/geometry/cylinder",
        ),
        ('<mass value="0.0"/>', '<mass value="-1"/>', "link[@name='arm']/inertial/mass/@value"),
        ('lower="-3.141592653589793" ', "", "joint[@name='shoulder']/limit"),
        ('<axis xyz="0 1 0"/>', '<axis xyz="0 0 0"/>', "joint[@name='shoulder']/axis/@xyz"),
        (
            "</robot>",
            '<joint name="j2" type="revolute"><parent link="arm"/><child link="arm"/></joint></robot>',
            "joint[@name='j2']/limit",
        ),
        ('<robot name="1dof">', '<robot name="1dof"', "not valid XML"),
    ],
)
def test_urdf_errors_name_the_element_and_attribute(tmp_path, old, new, where):
    assert old in _URDF
    bad = tmp_path / "bad.urdf"
    bad.write_text(_URDF.replace(old, new))
    with pytest.raises(RobotFileError) as err:
        load_robot(bad)
    assert where in str(err.value) and "\n" not in str(err.value)


def test_robot_files_are_read_by_suffix(tmp_path):
    (tmp_path / "robot.yaml").write_text("name: x\n")
    with pytest.raises(RobotFileError, match="neither .toml nor .urdf"):
        load_robot(tmp_path / "robot.yaml")
    with pytest.raises(RobotFileError, match="does not exist"):
        load_robot(tmp_path / "missing.urdf")


def test_urdf_fixed_and_continuous_joints_and_an_offset_stl_mesh(tmp_path):
    """A fixed joint is a joint locked at 0 (no coordinate); a continuous one turns fully; a mesh sits at its collision origin."""
    (tmp_path / "tet.stl").write_text(
        "solid t\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 0 1\n"
        "endloop\nendfacet\nendsolid t\n"
    )
    (tmp_path / "r.urdf").write_text("""<robot name="r">
      <link name="base"><inertial><mass value="2"/></inertial>
        <collision><geometry><box size="1 1 1"/></geometry></collision></link>
      <link name="plate"><collision><origin xyz="0 0 0.5"/><geometry><box size="1 1 0.1"/></geometry></collision></link>
      <link name="wheel"><inertial><mass value="1"/><origin xyz="0.1 0 0" rpy="0 1 0"/></inertial>
        <collision><origin xyz="0 0 2"/><geometry><mesh filename="tet.stl" scale="0.5 0.5 0.5"/></geometry></collision></link>
      <joint name="bolt" type="fixed"><parent link="base"/><child link="plate"/><origin xyz="0 0 1"/></joint>
      <joint name="spin" type="continuous"><parent link="plate"/><child link="wheel"/><axis xyz="0 1 0"/></joint>
    </robot>""")
    robot = load_robot(tmp_path / "r.urdf")
    assert robot.dof == 1 and [j.name for j in robot.joints] == ["spin"] and robot.locked == {"bolt": 0.0}
    assert robot.planar and np.allclose(np.degrees(robot.joint_bounds), [[-180, 180]])
    verts, com = robot.geometry(np.zeros(1))
    assert np.allclose(verts[-3:], [[0, 0, 3], [0, 0, 3.5], [0.5, 0, 3]])  # joint at z 1, mesh origin z 2, scale 0.5
    assert np.allclose(com, [0.1 / 3, 0, 1 / 3])  # wheel com at (0.1, 0, 1); the plate has no <inertial>: massless
