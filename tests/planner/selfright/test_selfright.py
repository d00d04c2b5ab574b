"""planner.selfright on the 1-DOF robot: searches, graphs, refinement and boundary energies against a grid and the physics."""

from __future__ import annotations

import numpy as np
import pytest

from planner.selfright.analysis import analyse, compare_graphs, home_state
from planner.selfright.crossing import crossing_energies
from planner.selfright.graph import grid_connections
from planner.selfright.probes import probe_states
from planner.selfright.search import adaptive_study, grid_study
from planner.selfright.space import to_unit
from sim.robots import StabilityFunction, load_robot


def test_one_dof_robot_graph_agrees_with_a_grid_search():
    robot = load_robot("examples/robots/1dof.toml")
    probes = probe_states(robot, 20.0, 150, 1)
    grid = grid_study(robot, 20.0, 3.0)
    g = analyse(grid, probes=probes)
    study = adaptive_study(robot, 20.0, 700, seed=0, r_min_deg=0.5)
    a = analyse(study, probes=probes)
    # whole hulls: every face of a queried joint state is a query; the last batch may overshoot by a hull
    assert 700 <= study.queries <= 700 + 12 and study.queries < grid.queries
    assert a.home >= 0 and g.home >= 0
    G = a.graph
    assert G.n_edges >= 3 and np.all(G.edges["energy"] > 0)
    assert (G.edges["dst"] == a.home).any()  # some region rights itself onto the home node
    c = compare_graphs(a, study, g, grid, probes)
    assert c.same and c.nodes_matched >= 4 and c.edges_matched >= 6
    # every state rights itself on this slope (test_quasi_static_sweep_confirms_the_one_dof_righting_path)
    assert a.rightable == g.rightable == 1.0 and c.rightable_agreement == 1.0
    # the adaptive search puts its boundary pairs closer than the grid's 3° spacing
    assert a.pair_length_deg < g.pair_length_deg


def test_a_tenth_of_the_grid_s_queries_gives_its_graph_with_closer_pairs():
    """Figure 5.3's claim on the 1-DOF robot: an order of magnitude fewer queries than the 1° grid, the same
    graph, and boundary pairs closer on average than the grid's 1° (benchmarks/selfright.py's setting;
    its figures over held-out seeds are in docs/benchmarks.md)."""
    robot = load_robot("examples/robots/1dof.toml")
    probes = probe_states(robot, 20.0, 500, 1)
    grid = grid_study(robot, 20.0, 1.0)
    g = analyse(grid, probes=probes)
    for seed in range(4):
        study = adaptive_study(
            robot, 20.0, 210, seed=seed, r_min_deg=0.5, r_max_deg=45.0, batch_size=10, refine=0.4, outcomes=True
        )
        assert study.queries * 10 <= grid.queries
        a = analyse(study, probes=probes)
        c = compare_graphs(a, study, g, grid, probes)
        assert c.same, f"seed {seed}: {c.nodes_matched} nodes, {c.edges_matched} edges matched"
        mine, grids = c.pair_length_deg  # means over the matched edges
        assert mine < 1.0 and mine < grids, f"seed {seed}: {mine:.2f}° against {grids:.2f}°"


def test_refinement_bisects_every_transition_pair_below_the_boundary_resolution():
    """Same budget, with and without the refinement: only with it is every edge's pair under r_min."""
    robot = load_robot("examples/robots/1dof.toml")
    plain = adaptive_study(robot, 20.0, 700, seed=0, r_min_deg=0.5, refine=0.0)
    refined = adaptive_study(robot, 20.0, 700, seed=0, r_min_deg=0.5, refine=0.1)
    assert abs(refined.queries - plain.queries) <= 12  # one hull either way
    assert refined.refine_rounds >= 2 and 0 < refined.refine_queries <= 70 + 12
    # the search labels whole hulls; a refinement query is one state on its pair's face, not a hull
    faces_per_joint_state = [np.unique(s.X[:, : s.n_free], axis=0, return_counts=True)[1] for s in (plain, refined)]
    assert np.all(faces_per_joint_state[0] > 1)
    assert np.sum(faces_per_joint_state[1] == 1) == refined.refine_queries
    a, b = analyse(plain), analyse(refined)
    la, lb = np.degrees(a.graph.edges["length"]), np.degrees(b.graph.edges["length"])
    assert la.max() > 0.5 and lb.max() <= 0.5
    assert b.n_edges >= a.n_edges and b.pair_length_deg < a.pair_length_deg
    with pytest.raises(ValueError, match="refine"):
        adaptive_study(robot, 20.0, 100, refine=1.0)


def _sweep(F, theta0: float, phi0: float, theta1: float, step: float = 0.05):
    """Move the 1-DOF robot's joint quasi-statically from theta0 to theta1 (degrees), resting on the
    face below; returns [(theta, energy lost, resting face)] at every tip and the final face."""
    phi = F(np.radians([[theta0]]), np.radians([[phi0]])).rest[0]
    events, face = [], None
    for t in np.arange(theta0, theta1, step if theta1 > theta0 else -step):
        r = F(np.radians([[t]]), phi[None])
        if r.energy[0] > 1e-6:
            events.append((t, float(r.energy[0]), int(r.rest_id[0])))
        phi, face = r.rest[0], int(r.rest_id[0])
    return events, face


def test_quasi_static_sweep_confirms_the_one_dof_righting_path():
    """The graph's claims checked against the physics directly, joint step by joint step.

    On a 20° slope the robot resting near -170° pitch at joint -10° does not tip as the joint
    comes down: its face splits in two at -14.5° (a corner pierces it) and it settles on the
    stable half without losing energy, then tips onto the home face at about -56° (38.6 J).
    Both graphs must say the same: one node from -10° to -56°, an edge of 38.6 J home.
    """
    robot = load_robot("examples/robots/1dof.toml")
    F = StabilityFunction(robot, 20.0)
    events, _ = _sweep(F, -10.0, -170.0, -70.0)
    assert len(events) == 1 and -57.0 < events[0][0] < -55.0 and abs(events[0][1] - 38.58) < 0.05
    grid = grid_study(robot, 20.0, 1.0)
    home_U, home_id = home_state(grid, with_id=True)
    g = analyse(grid, probes=np.zeros((0, 2)))
    G = g.graph
    start = F(np.radians([[-10.0]]), np.radians([[-170.0]]))
    U = grid.embed(to_unit([np.radians(-10.0), start.start[0][0]], grid.bounds[:, 0], grid.bounds[:, 1])[None])
    n = G.node_of(U, ids=[start.start_id[0]])[0]
    cost, _ = G.costs_to(g.home)
    assert G.node_of(grid.embed(home_U[None]), ids=[home_id])[0] == g.home != n
    assert abs(cost[n] - 38.58) < 0.05  # one transition home, the one the sweep found
    # and the robot resting on the merged face near +90° rolls on as one region until its face tips at +2.6°
    events, _ = _sweep(F, -25.0, 93.0, 5.0)
    assert len(events) == 1 and 2.0 < events[0][0] < 3.0


def test_grid_connections_join_neighbouring_joint_states_on_one_face_or_its_replacement():
    grid = grid_study(load_robot("examples/robots/1dof.toml"), 20.0, 3.0)
    i, j = grid_connections(grid)
    N = len(grid.X)
    k = np.rint(grid.X[:, 0] * 120).astype(int) % 120  # 3° steps round a full turn
    faces_at = {}
    for n in range(N):
        faces_at.setdefault(k[n], set()).add(int(grid.ids[n]))
    ev = (i < N) & (j < N)
    a, b = i[ev], j[ev]
    assert np.all((k[b] - k[a]) % 120 == 1)  # only the next grid joint state
    same = grid.ids[a] == grid.ids[b]
    assert same.mean() > 0.9
    for x, y in zip(a[~same], b[~same]):  # continuations: each face is gone where the other one is
        assert int(grid.ids[y]) not in faces_at[k[x]] and int(grid.ids[x]) not in faces_at[k[y]]
    # a resting state is the evaluated state on its resting face
    settled = np.flatnonzero(np.isfinite(grid.rest).all(axis=1))
    r = i[i >= N] - N
    assert np.array_equal(grid.ids[j[i >= N]], grid.rest_ids[settled[r]])


def test_crossing_energies_are_the_boundary_s_whatever_the_grid_spacing():
    """A witness lies up to a grid step past the boundary, so a coarse grid reports other energies;
    bisected to the boundary, the 3° and the 10° grids' transitions lose the same, and the one home
    from the region the sweep starts in loses what the sweep does (38.58 J)."""
    robot = load_robot("examples/robots/1dof.toml")
    out = {}
    for res in (3.0, 10.0):
        grid = grid_study(robot, 20.0, res)
        g = analyse(grid, probes=np.zeros((0, 2)))
        c = crossing_energies(grid, g, tol_deg=0.01)
        assert len(c.energy) == g.n_edges and np.all(c.pairs <= len(g.graph.all_transitions["src"]))
        assert np.isfinite(c.energy).sum() >= 5 and np.array_equal(c.reported, g.graph.edges["energy"])
        out[res] = c
    fine, coarse = out[3.0], out[10.0]
    at = np.isfinite(coarse.energy)
    nearest = lambda v, ref: np.min(np.abs(ref[np.isfinite(ref)][None, :] - v[:, None]), axis=1)  # noqa: E731
    assert np.all(nearest(coarse.energy[at], fine.energy) < 0.01)
    assert np.max(nearest(coarse.reported[at], fine.reported)) > 0.5  # what the grids report disagrees
    assert np.any(np.abs(fine.energy - 38.58) < 0.01)
