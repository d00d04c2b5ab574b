"""rapt-plan generate on small budgets: each stage, the plan file, determinism, resume, errors."""

import json
import re
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import sim
from planner.cli import app
from planner.generate import PLAN_SCHEMA, GenerateConfig, analyse, generate, search_mission, select_pairs

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
runner = CliRunner()


@pytest.fixture(scope="module")
def range2017():
    return sim.load_mission(EXAMPLES / "range2017.toml")


def small(tmp_path, **kw):
    base = dict(budget=1000, batch_size=250, dithers=60, pairs=4, store=tmp_path / "study.db")
    base.update(kw)
    return GenerateConfig(**base)


def test_stages_search_analyse_and_select_distinct_sub_boundaries(range2017, tmp_path):
    cfg = small(tmp_path)
    study = search_mission(range2017, cfg)
    assert study.n_evaluated == 1000 and len(study.X_failed) > 0  # invalid scenarios are kept out
    a = analyse(range2017, study)
    assert set(np.unique(a.result.modes)) >= {0, 1, 3}
    assert set(a.sensitivity) == {"mission_success", "safety_success"}
    assert max(a.sensitivity["mission_success"], key=a.sensitivity["mission_success"].get) in range2017.space.names
    pairs = select_pairs(a, 4)
    keys = {(p["level"], tuple(p["elements"])) for p in pairs}
    assert len(pairs) == 4 and len(keys) == 4  # four different sub-boundaries
    for p in pairs:
        i, j = p["rows"]
        assert p["modes"][0] != p["modes"][1] or p["level"] > 0
        changed = [n for n in p["elements"] if a.result.column(n)[i] != a.result.column(n)[j]]
        assert changed == p["elements"]  # the pair really flips these elements


def test_generate_writes_a_plan_whose_predictions_hold(range2017, tmp_path):
    plan = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "out", small(tmp_path))
    on_disk = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert on_disk == json.loads(json.dumps(plan)) and plan["schema"] == PLAN_SCHEMA
    assert {"mission", "study", "sensitivity", "pairs", "scenarios", "run_order"} <= set(plan)
    assert len(plan["scenarios"]) == 2 * len(plan["pairs"])
    assert plan["run_order"] == [s["id"] for s in plan["scenarios"]] + [v["id"] for v in plan["variants"]]
    assert (tmp_path / "out" / "report.html").is_file()
    U = np.array([s["u"] for s in plan["scenarios"]])
    again = sim.simulate(range2017, U)
    for s, mode in zip(plan["scenarios"], again.modes):
        assert s["predicted"]["mode"] == ("TF", "SS", "MS", "TS")[mode]
        d = s["dithering"]
        assert 0 <= d["p_predicted_mode"] <= 1 and d["runs"] == 30
        for kind, name in s["files"].items():
            assert (tmp_path / "out" / name).is_file(), kind
        assert set(s["parameters"]) == set(range2017.space.names)


def test_same_seed_same_plan(range2017, tmp_path):
    a = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "a", small(tmp_path / "a"))
    b = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "b", small(tmp_path / "b"))
    assert a == b


def test_cli_generate_resume_and_errors(tmp_path):
    out = tmp_path / "plan"
    args = ["generate", str(EXAMPLES / "imitation7.toml"), "--out", str(out), "--budget", "600",
            "--batch-size", "200", "--dithers", "40", "--pairs", "2"]
    first = runner.invoke(app, args)
    assert first.exit_code == 0, first.output
    assert "field plan in" in first.output and (out / "plan.json").is_file()
    refused = runner.invoke(app, args)
    assert refused.exit_code == 2 and "--resume" in refused.output
    plan_before = (out / "plan.json").read_text()
    again = runner.invoke(app, args + ["--resume"])  # the stored runs are reused, not re-run
    assert again.exit_code == 0, again.output
    assert re.search(r"\d+ valid runs", again.output) and (out / "plan.json").read_text() == plan_before
    bad = tmp_path / "bad.toml"
    bad.write_text((EXAMPLES / "imitation7.toml").read_text().replace("[vehicle]", "[vehicle]\ncruize_speed = 2.0", 1))
    for argv, expect in [(["generate", str(bad), "--out", str(tmp_path / "x")], "cruize_speed"),
                         (["generate", str(tmp_path / "none.toml"), "--out", str(tmp_path / "x")], "MISSION_FILE"),
                         (["generate", str(EXAMPLES / "imitation7.toml"), "--out", str(tmp_path / "y"),
                           "--budget", "100"], "--budget")]:
        result = runner.invoke(app, argv)
        assert result.exit_code == 2, (argv, result.output)
        assert expect in result.output and "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1


def test_same_plan_with_processes_and_a_dask_cluster(range2017, tmp_path):
    from distributed import Client, LocalCluster

    from planner.generate import make_executor

    cfg = dict(budget=1000, batch_size=250, dithers=0, pairs=3)
    base = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "local", GenerateConfig(**cfg))
    pool, close = make_executor("processes")
    try:
        procs = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "procs", GenerateConfig(**cfg, executor=pool))
    finally:
        close()
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      host="127.0.0.1") as cluster, Client(cluster) as client:
        dask = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "dask", GenerateConfig(**cfg, executor=client))
    assert base == procs == dask


def test_refine_sharpens_pairs_and_variants_keep_their_mode(range2017, tmp_path):
    from planner.generate import refine_pair

    cfg = small(tmp_path)
    a = analyse(range2017, search_mission(range2017, cfg))
    refined = [(p, refine_pair(range2017, a, p, runs=12, min_distance=0.02)) for p in select_pairs(a, 4)]
    refined = [(p, q) for p, q in refined if q.get("refined")]
    assert refined  # bisection stops early only at a third behaviour or an invalid scenario
    pair, sharp = refined[0]
    assert 0.02 <= sharp["distance"] < pair["distance"] / 4
    lo, hi = sharp["u_override"]
    r = sim.simulate(range2017, np.vstack([lo, hi]))
    cols = [r.names.index(e) for e in pair["elements"]]
    i, j = pair["rows"]
    np.testing.assert_array_equal(r.scores[0, cols], a.result.scores[i, cols])  # still the same sub-boundary
    np.testing.assert_array_equal(r.scores[1, cols], a.result.scores[j, cols])
    plan = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "out",
                    small(tmp_path, dithers=100, refine=8, pairs=2, fragile_below=0.9))
    for v in plan["variants"]:
        assert v["p_predicted_mode"] >= 0.9 and v["variant_of"] in plan["run_order"]
        mode = sim.simulate(range2017, np.array(v["u"])[None, :]).modes[0]
        assert ("TF", "SS", "MS", "TS")[mode] == v["predicted"]["mode"]
