"""Self-righting (chapter 5): adaptive manifold sampling against grid search, Gabriel clustering against PRM.

Three parts, each printed as a table (and 1b: the 1-DOF graph over seeds 0-7 at part 1's
setting and the settings it was chosen against, then on held-out seeds 24-119):

1. Figure 5.3 — the 1-, 2- and 3-DOF robots of Figure 5.2 (1-DOF on a 20° slope, the
   others flat): a grid search (every hull face of every joint state on a grid: 1° for
   1 and 2 DOF; 6° for 3 DOF, or the paper's 3° with ``--fine``: 10.5 million queries,
   about 12 minutes and 7 GB more) against the
   manifold-constrained adaptive search (Algorithms 6-7; 1 DOF at a tenth of the grid's
   queries, told where states tip: ``ONE_DOF_TENTH``).  A query is the stability of one
   state [θ, face] — the grid's ``||Z_θ|| (π/r)^m`` of section 5.5.2 — for both: the
   adaptive search labels every face of each joint state it picks (whole hulls).  Graphs:
   the grid's from its own neighbours (same face, or the face replacing it, at the next
   grid joint state: the original framework), the adaptive one's from a Gabriel graph
   with face identities (Algorithm 8).  Matched through the truly stable hull faces of
   500 random joint states ("probe states": a node of one graph maps to the node of the
   other most of its probes fall in; nodes under 1 % of the probes ignored).  Per method:
   queries, graph size, nodes/edges matched, the self-rightable share of probe states
   (and the share whose verdict agrees), the mean boundary-pair length (joint space) and
   transition energy over all boundary pairs, and both again over the matched edges; then
   the matched edges' energies at the boundary itself (each method's pairs bisected to
   0.01° by :func:`~planner.selfright.crossing.crossing_energies`, "m.bdy") and how far the reported
   energy lies from it ("m.err"): a witness up to a grid step past the boundary stands on a
   face that has turned, and can lose less (or more) than the crossing does.
2. Table 5.1 — building the graph from the adaptive sample sets: Gabriel-graph
   clustering (Algorithm 8) against PRM-style connection (:mod:`planner.selfright.prm`):
   every pair of stable known states within the same ``d_max`` is checked with a linear
   local planner, one path state every 1° (each snapped to its face, which must be stable
   and stay on one manifold), all of them run, in numpy batches; and whether the PRM's
   components, with Algorithm 8's transitions, make the same graph.  Without part 1
   (``--skip fig53``) the adaptive studies run alone, without their grids.
3. Figure 5.6 — the 5-DOF manipulator robot (Figure 5.5) with 1 to 5 active joints
   (shoulder pitch; + shoulder yaw; + elbow; + wrist; + jaw; inactive joints held at home,
   the elbow at full extension, 180°, as the text has it): queries until the resolution
   cut-offs end the search, mean hull faces per joint state, the self-rightable fraction
   and mean transition energy to the home state over every hull face of random joint states
   and over random joint states dropped in random orientations (split by how the robot
   lies: upright, upside down, on a side, on an end), and the queries a 5° grid would need
   (mean hull faces × grid points, as in section 5.5.2).

Run:  python benchmarks/selfright.py [--quick | --fine] [--robots 1dof ...] [--skip fig56 ...]
      (full: about 10 minutes on 2 cores; quick: about 2; ``--robots 1dof --skip fig56``: seconds)
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from planner.selfright.analysis import analyse, compare_graphs
from planner.selfright.crossing import crossing_energies
from planner.selfright.prm import prm_connect, same_graph
from planner.selfright.probes import orientation_probes, probe_states
from planner.selfright.search import adaptive_study, grid_study
from sim.robots import down_normals, load_robot

ROBOTS = "examples/robots"
# 1 DOF at a tenth of the grid's 2,153 queries: coarse interiors, small batches, 40 % kept for the
# refinement, and the search told where states tip (chosen on seeds 0-23; part 1b checks it on 24-119)
ONE_DOF_TENTH = dict(budget=210, r_min_deg=0.5, r_max_deg=45.0, batch_size=10, refine=0.4, outcomes=True)


def cases(quick: bool, fine: bool = False) -> list:
    """Figure 5.3's robots: name, slope, grid resolution (deg), adaptive options."""
    return [
        ("1dof", 20.0, 1.0, dict(ONE_DOF_TENTH)),
        ("2dof", 0.0, 3.0 if quick else 1.0, dict(budget=10000 if quick else 30000, r_min_deg=0.5, r_max_deg=10.0)),
        (
            "3dof",
            0.0,
            12.0 if quick else 3.0 if fine else 6.0,
            dict(budget=10000 if quick else 40000, r_min_deg=2.0, r_max_deg=15.0, batch_size=100),
        ),
    ]


def adaptive_only(quick: bool, seed: int, robots: list[str] | None = None) -> list:
    """Figure 5.3's adaptive studies without the grids (Table 5.1 alone needs no more): (name, study, analysis, s)."""
    studies = []
    for name, slope, _res, opts in [c for c in cases(quick) if robots is None or c[0] in robots]:
        robot = load_robot(f"{ROBOTS}/{name}.toml")
        opts = dict(opts)
        ad = adaptive_study(robot, slope, opts.pop("budget"), seed=seed, **opts)
        studies.append((name, ad, analyse(ad), ad.seconds))
    return studies


def fig53(quick: bool, seed: int, robots: list[str] | None = None, fine: bool = False) -> list:
    print(
        "1. Figure 5.3: grid search against adaptive manifold sampling (a query = one [joint state, face]; "
        "graphs matched on probe states)"
    )
    print(
        f"{'robot':>5} {'method':>9} {'queries':>9} {'time s':>7} {'nodes':>5} {'edges':>5} {'matched n/e':>13} "
        f"{'rightable':>9} {'agree':>6} {'pairs':>6} {'pair deg':>8} {'energy J':>8} {'m.pair deg':>10} {'m.energy J':>10} "
        f"{'m.bdy J':>8} {'m.err J':>7}"
    )
    studies = []
    for name, slope, res, opts in [c for c in cases(quick, fine) if robots is None or c[0] in robots]:
        robot = load_robot(f"{ROBOTS}/{name}.toml")
        probes = probe_states(robot, slope, 300 if quick else 500, seed + 1)
        grid = grid_study(robot, slope, res)
        t0 = time.perf_counter()
        g = analyse(grid, probes=probes)
        grid_seconds = grid.seconds + time.perf_counter() - t0
        budget = opts.pop("budget")
        ad = adaptive_study(robot, slope, budget, seed=seed, **opts)
        t0 = time.perf_counter()
        a = analyse(ad, probes=probes)
        ad_seconds = ad.seconds + time.perf_counter() - t0
        c = compare_graphs(a, ad, g, grid, probes)
        # the matched edges' energies at the boundary itself (each method's pairs bisected to 0.01°), and how far
        # what each method reports lies from its own boundary figure
        ce = [crossing_energies(study, r) for study, r in ((ad, a), (grid, g))]
        at = c.matched_edges.T
        both = np.isfinite(ce[0].energy[at[0]]) & np.isfinite(ce[1].energy[at[1]])  # resolved in both
        mean = lambda v: float(v.mean()) if v.size else float("nan")  # noqa: E731
        bdy = [mean(x.energy[i][both]) for x, i in zip(ce, at)]
        err = [mean(np.abs(x.reported[i] - x.energy[i])[both]) for x, i in zip(ce, at)]
        for k, (_study, r, label, secs) in enumerate(
            ((grid, g, grid.method, grid_seconds), (ad, a, "adaptive", ad_seconds))
        ):
            T = r.graph.all_transitions
            matched = (
                f"{c.nodes_matched}/{c.n_nodes[0]}/{c.n_nodes[1]} {c.edges_matched}/{c.n_edges[0]}/{c.n_edges[1]}"
                if k
                else ""
            )  # matched / adaptive's / grid's (nodes over 1 % of probes, edges between them)
            agree = f"{c.rightable_agreement:.1%}" if k else ""
            print(
                f"{name:>5} {label:>9} {r.queries:>9,} {secs:>7.1f} {r.n_nodes:>5} {r.n_edges:>5} {matched:>13} "
                f"{r.rightable:>9.1%} {agree:>6} {len(T['length']):>6,} {np.degrees(T['length']).mean():>8.2f} "
                f"{T['energy'].mean():>8.2f} {c.pair_length_deg[1 - k]:>10.2f} {c.transition_energy[1 - k]:>10.2f} "
                f"{bdy[1 - k]:>8.3f} {err[1 - k]:>7.3f}",
                flush=True,
            )
        stop = "resolution reached" if ad.stopped_by_resolution else "budget spent"
        pg = np.degrees(g.graph.all_transitions["length"]).mean() / np.degrees(a.graph.all_transitions["length"]).mean()
        eg = g.graph.all_transitions["energy"].mean() / a.graph.all_transitions["energy"].mean()
        print(
            f"{'':>5} {'ratio':>9} {g.queries / a.queries:>8.1f}x {'':>7} {'':>5} {'':>5} "
            f"{'same' if c.same else 'differs':>13} {'':>9} {'':>6} {'':>6} {pg:>7.2f}x {eg:>7.2f}x "
            f"{c.pair_length_deg[1] / c.pair_length_deg[0]:>9.2f}x {c.transition_energy[1] / c.transition_energy[0]:>9.2f}x"
            f" {bdy[1] / bdy[0]:>7.3f}x {err[1] / err[0] if err[0] else float('inf'):>6.0f}x"
            f"   grid/adaptive ({stop}, {ad.joint_states:,} joint states)",
            flush=True,
        )
        studies.append((name, ad, a, ad_seconds))
    return studies


def one_dof_seeds(seeds: int = 8, held_out: range = range(24, 120)) -> None:
    """Figure 5.3's 1-DOF check over seeds: part 1's setting (a tenth of the grid's queries, told where states
    tip) beside the settings it was chosen against, on seeds 0-7; then the chosen settings on seeds the choice
    never saw (it was made on seeds 0-23)."""
    robot = load_robot(f"{ROBOTS}/1dof.toml")
    probes = probe_states(robot, 20.0, 500, 1)
    grid = grid_study(robot, 20.0, 1.0)
    g = analyse(grid, probes=probes)
    print(
        f"\n1b. 1 DOF against the 1° grid ({g.queries:,} queries): how often the graph is the same, and the "
        "matched pairs and energies when it is"
    )
    print(
        f"{'setting':<66} {'seeds':>7} {'queries':>8} {'ratio':>6} {'same':>7} {'m.pair deg':>10} "
        f"{'m.energy/grid':>13} {'ended by':>10}"
    )
    first = range(seeds)
    settings = (
        ("budget 700, r_min 0.5°, r_max 10°, batch 50, refine 0.1", first, dict(budget=700, r_min_deg=0.5)),
        ("the same, until the resolution cut-offs end it (budget 5,000)", first, dict(budget=5000, r_min_deg=0.5)),
        ("budget 210, r_min 0.5°, r_max 45°, batch 10, refine 0.4", first, dict(ONE_DOF_TENTH, outcomes=False)),
        ("the same, told where states tip (outcomes): part 1's setting", first, dict(ONE_DOF_TENTH)),
        ("the same with refine 0.5", first, dict(ONE_DOF_TENTH, refine=0.5)),
        ("part 1's setting with budget 300", first, dict(ONE_DOF_TENTH, budget=300)),
        ("part 1's setting, held-out seeds", held_out, dict(ONE_DOF_TENTH)),
        ("part 1's setting with budget 300, held-out seeds", held_out, dict(ONE_DOF_TENTH, budget=300)),
    )
    for label, seed_range, opts in settings:
        queries, same, pair, energy, converged = [], 0, [], [], 0
        for seed in seed_range:
            ad = adaptive_study(robot, 20.0, seed=seed, **opts)
            converged += bool(ad.stopped_by_resolution)
            a = analyse(ad, probes=probes)
            c = compare_graphs(a, ad, g, grid, probes)
            queries.append(a.queries)
            if c.same:
                same += 1
                pair.append(c.pair_length_deg[0])
                energy.append(c.transition_energy[0] / c.transition_energy[1])
        q = float(np.mean(queries))
        n = len(seed_range)
        print(
            f"{label:<66} {f'{seed_range[0]}-{seed_range[-1]}':>7} {q:>8.0f} {g.queries / q:>5.1f}x "
            f"{f'{same}/{n}':>7} {np.mean(pair) if pair else float('nan'):>10.2f} "
            f"{np.mean(energy) if energy else float('nan'):>12.3f}x "
            f"{f'cut-offs {converged}' if converged else 'budget':>10}",
            flush=True,
        )


def table51(studies) -> None:
    """Table 5.1: Gabriel clustering against the PRM's linear local planner on every candidate edge (1° steps)."""
    print(
        "\n2. Table 5.1: building the graph from the adaptive sample sets: Gabriel clustering against PRM edge "
        "checking (every pair within d_max, 1° steps)"
    )
    print(
        f"{'robot':>5} {'search s':>8} {'known states':>12} {'d_max deg':>9} {'Gabriel s':>9} {'PRM s':>8} "
        f"{'PRM/Gabriel':>11} {'edges':>10} {'connected':>9} {'path states':>12} {'evaluated':>11} "
        f"{'nodes G/P':>9} {'matched n/e':>11} {'states agree':>12} {'graph':>7}"
    )
    for name, study, result, search_s in studies:
        gab = result.graph_seconds  # analyse() built the graph (with its face identities) and timed it
        prm = prm_connect(study, result)
        same = same_graph(result, study, prm)
        print(
            f"{name:>5} {search_s:>8.1f} {result.n_known_states:>12,} {np.degrees(result.max_edge):>9.1f} "
            f"{gab:>9.2f} {prm.seconds:>8.1f} {prm.seconds / gab:>10.0f}x {prm.edges_checked:>10,} "
            f"{prm.edges_connected:>9,} {prm.path_states:>12,} {prm.evaluations:>11,} "
            f"{f'{same.nodes[0]}/{same.nodes[1]}':>9} {f'{same.nodes_matched}/{same.edges_matched}':>11} "
            f"{same.states_agreeing:>11.1%} {'same' if same.same else 'differs':>7}",
            flush=True,
        )


def _lying(study, probes) -> np.ndarray:
    """How each probe state lies, by the base's axis nearest the down direction: 0 upright, 1 upside down,
    2 on a side, 3 on an end (nose or tail down)."""
    body = study.bounds[study.n_free :, 0] + probes.U[:, study.n_free :] * np.ptp(study.bounds[study.n_free :], axis=1)
    down = down_normals(body, False)
    axis = np.argmax(np.abs(down), axis=1)
    return np.select([axis == 2, axis == 1, axis == 0], [np.where(down[:, 2] < 0, 0, 1), 2, 3])


def draw_fig56(rows: list[dict], path: str = "docs/reproduction/fig5_6.png") -> None:
    """Figure 5.6 as a PNG: (a) queries against active joints, with the 5° grid's estimate; (b) mean energy to
    home; (c) the self-rightable share (the paper's 78 % and 100 % marked)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = [r["m"] for r in rows]
    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
    ax[0].semilogy(m, [r["queries"] for r in rows], "o-", label="adaptive (ours)")
    ax[0].semilogy(m, [r["grid"] for r in rows], "s--", color="tab:gray", label="5° grid (estimate)")
    ax[0].set(title="(a) queries", xlabel="active joints", ylabel="queries")
    for key, label in (("energy", "every hull face"), ("energy_o", "random orientations")):
        ax[1].plot(m, [r[key] for r in rows], "o-", label=label)
    ax[1].set(title="(b) mean energy to reach home", xlabel="active joints", ylabel="J")
    for key, label in (("rightable", "every hull face"), ("rightable_o", "random orientations")):
        ax[2].plot(m, [100 * r[key] for r in rows], "o-", label=label)
    ax[2].plot(m, [78 if k == 1 else 100 for k in m], "k*", markersize=10, label="dissertation")
    ax[2].set(title="(c) self-rightable", xlabel="active joints", ylabel="% of states", ylim=(0, 105))
    for a in ax:
        a.set_xticks(m)
        a.legend(fontsize=8)
    fig.suptitle("Figure 5.6: the 5-DOF robot, joints added one at a time (benchmarks/selfright.py)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fig56(quick: bool, seed: int, budget: int | None = None) -> list[dict]:
    """Figure 5.6: inactive joints held at their home (the elbow at full extension, 180°, as the text has it).

    The self-rightable share is counted two ways: over every hull face of random joint states
    (each face once, however small), and over random joint states dropped in random
    orientations (each face by the share of orientations landing on it; also split by how
    the robot lies)."""
    robot = load_robot(f"{ROBOTS}/5dof.toml")
    order = ["shoulder_pitch", "shoulder_yaw", "elbow", "wrist", "jaw"]
    home = {j.name: j.home for j in robot.all_joints}
    budget = budget or (1000 if quick else 4000)
    print(
        f"\n3. Figure 5.6: 5-DOF manipulator robot, flat ground, active joints added one at a time, the others at "
        f"home (elbow at full extension) (adaptive: r_min 3°, r_max 20°, at most {budget:,} queries)"
    )
    print(
        f"{'active':>6} {'joints':<52} {'queries':>8} {'stopped by':>10} {'time s':>7} {'nodes':>5} {'faces':>5} "
        f"{'rightable':>9} {'energy J':>8} {'by orient.':>10} {'energy J':>8} "
        f"{'upright/inverted/side/end':>25} {'5° grid (est.)':>14}"
    )
    rows: list[dict] = []
    for m in range(1, 6):
        r = robot.lock({n: home[n] for n in order[m:]})
        study = adaptive_study(r, 0.0, budget, seed=seed, r_min_deg=3.0, r_max_deg=20.0, batch_size=100, refine=0.0)
        res = analyse(study, probes=probe_states(r, 0.0, 150 if quick else 300, seed + 1))
        drop = orientation_probes(r, 0.0, 300 if quick else 1000, seed + 1)
        by_orientation = analyse(study, probes=drop)
        lying = _lying(study, drop)
        split = "/".join(f"{by_orientation.probe_rightable[lying == k].mean():.0%}" for k in range(4))
        faces = np.mean([len(f) for f in study.faces])
        grid = faces * np.prod([np.ptp(b) / np.radians(5.0) for b in r.joint_bounds])
        stop = "resolution" if study.stopped_by_resolution else "budget"
        rows.append(
            dict(
                m=m,
                queries=study.queries,
                grid=grid,
                energy=res.energy_to_home,
                energy_o=by_orientation.energy_to_home,
                rightable=res.rightable,
                rightable_o=by_orientation.rightable,
            )
        )
        print(
            f"{m:>6} {', '.join(j.name for j in r.joints):<52} {study.queries:>8,} {stop:>10} {study.seconds:>7.1f} "
            f"{res.n_nodes:>5} {faces:>5.0f} {res.rightable:>9.1%} {res.energy_to_home:>8.2f} "
            f"{by_orientation.rightable:>10.1%} {by_orientation.energy_to_home:>8.2f} {split:>25} {grid:>14,.0f}",
            flush=True,
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller budgets and coarser grids (about a minute)")
    ap.add_argument("--fine", action="store_true", help="the 3-DOF grid at the paper's 3° (10.5 million queries)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--budget56", type=int, default=None, help="Figure 5.6's query budget per row (default 4,000; --quick 1,000)"
    )
    ap.add_argument("--skip", nargs="*", default=[], choices=["fig53", "table51", "fig56"])
    ap.add_argument(
        "--robots",
        nargs="+",
        default=None,
        choices=["1dof", "2dof", "3dof"],
        help="Figure 5.3 and Table 5.1 on these robots only (1dof alone takes seconds)",
    )
    args = ap.parse_args()
    t0 = time.perf_counter()
    if args.quick and args.fine:
        ap.error("--quick and --fine: choose one")
    studies = fig53(args.quick, args.seed, args.robots, args.fine) if "fig53" not in args.skip else []
    if "fig53" not in args.skip and not args.quick and (args.robots is None or "1dof" in args.robots):
        one_dof_seeds()
    if "table51" not in args.skip:
        table51(studies or adaptive_only(args.quick, args.seed, args.robots))
    if "fig56" not in args.skip:
        rows = fig56(args.quick, args.seed, args.budget56)
        if not args.quick:
            draw_fig56(rows)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
