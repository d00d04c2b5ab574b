"""rapt-plan generate on small budgets: each stage, the plan file, determinism, resume, errors."""

import hashlib
import json
import shutil
from collections import deque
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from typer.testing import CliRunner

import planner
import sim.uuv
from planner.common.plans import PLAN_SCHEMA
from planner.plan.analysis import analyse, select_pairs
from planner.plan.generate import GenerateConfig, generate, search_mission
from rapt.errors import InputError

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
SCHEMA = json.loads((Path(planner.__file__).parent / "plan.schema.json").read_text())
PLAN_VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)
runner = CliRunner()


def test_plan_schema_is_valid_and_rejects_what_the_planner_never_writes(plan_dir):
    jsonschema.Draft202012Validator.check_schema(SCHEMA)
    assert SCHEMA["properties"]["schema"]["const"] == PLAN_SCHEMA
    _, plan = plan_dir
    bad = json.loads(json.dumps(plan))
    bad["scenarios"][0]["predicted"]["mode"] = "XX"
    bad["pairs"][0]["extra"] = 1
    bad["scenarios"][1]["u"][0] = 1.5
    errors = {tuple(e.absolute_path) for e in PLAN_VALIDATOR.iter_errors(bad)}
    assert errors == {("scenarios", 0, "predicted", "mode"), ("pairs", 0), ("scenarios", 1, "u", 0)}


@pytest.fixture(scope="module")
def range2017():
    return sim.uuv.load_mission(EXAMPLES / "range2017.toml")


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


@pytest.fixture(scope="module")
def plan_dir(range2017, tmp_path_factory):
    out = tmp_path_factory.mktemp("plan")
    cfg = small(out, budget=1200, pairs=3, refine=40, fragile_below=0.5)
    plan = generate(range2017, EXAMPLES / "range2017.toml", out / "out", cfg)
    return out, plan


def test_generate_writes_a_plan_whose_predictions_hold(range2017, plan_dir):
    tmp_path, plan = plan_dir
    on_disk = json.loads((tmp_path / "out" / "plan.json").read_text())
    assert on_disk == json.loads(json.dumps(plan)) and plan["schema"] == PLAN_SCHEMA
    PLAN_VALIDATOR.validate(on_disk)  # the published schema describes what we write
    assert {"mission", "study", "sensitivity", "pairs", "scenarios", "run_order"} <= set(plan)
    text = (EXAMPLES / "range2017.toml").read_text()
    assert plan["mission"]["toml"] == text  # the plan carries its mission
    assert plan["mission"]["sha256"] == hashlib.sha256(text.encode()).hexdigest()
    assert len(plan["scenarios"]) == 2 * len(plan["pairs"])
    assert plan["run_order"] == [s["id"] for s in plan["scenarios"]] + [v["id"] for v in plan["variants"]]
    assert (tmp_path / "out" / "report.html").is_file()
    U = np.array([s["u"] for s in plan["scenarios"]])
    again = sim.uuv.simulate(range2017, U)
    for s, mode in zip(plan["scenarios"], again.modes):
        assert s["predicted"]["mode"] == ("TF", "SS", "MS", "TS")[mode]
        d = s["dithering"]
        assert 0 <= d["p_predicted_mode"] <= 1 and d["runs"] == 30
        for kind, name in s["files"].items():
            assert (tmp_path / "out" / name).is_file(), kind
        assert set(s["parameters"]) == set(range2017.space.names)


@pytest.mark.slow
def test_same_plan_with_processes_and_a_dask_cluster(range2017, tmp_path):
    from distributed import Client, LocalCluster

    from planner.plan.generate import make_executor

    cfg = dict(budget=500, batch_size=250, dithers=0, pairs=3)
    base = generate(range2017, EXAMPLES / "range2017.toml", tmp_path / "local", GenerateConfig(**cfg))
    pool, close = make_executor("processes")
    try:
        procs = generate(
            range2017, EXAMPLES / "range2017.toml", tmp_path / "procs", GenerateConfig(**cfg, executor=pool)
        )
    finally:
        close()
    with (
        LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None, host="127.0.0.1"
        ) as cluster,
        Client(cluster) as client,
    ):
        dask = generate(
            range2017, EXAMPLES / "range2017.toml", tmp_path / "dask", GenerateConfig(**cfg, executor=client)
        )
    assert base == procs == dask


def test_refined_pairs_are_sharp_counted_in_the_budget_and_every_side_holds_or_says_why(range2017, plan_dir):
    _, plan = plan_dir  # 1,200 runs, 40 per candidate, 3 pairs wanted, sides must hold at P >= 0.5
    target = plan["study"]["dithering"]["target"]
    runs, ref = plan["study"]["runs"], plan["study"]["refinement"]
    assert target == 0.5 and runs["search"] + 40 * 6 == 1200 and runs["refinement"] == ref["runs"] <= 40 * 6
    assert ref["sharp"] >= len(plan["pairs"]) and len(ref["dropped"]) == ref["candidates"] - ref["sharp"]
    by_id = {s["id"]: s for s in plan["scenarios"] + plan["variants"]}
    assert 1 <= len(plan["pairs"]) <= 3 and {p["verdict"] for p in plan["pairs"]} <= {"sharp", "robust", "fragile"}
    for p in plan["pairs"]:
        assert p["refined"] and 0.02 <= p["distance"] <= 0.05 < p["refinement"]["start_distance"]
        a, b = (by_id[s] for s in p["scenarios"])
        r = sim.uuv.simulate(range2017, np.array([a["u"], b["u"]]))
        cols = [r.names.index(e) for e in p["elements"]]
        assert not np.array_equal(r.scores[0, cols], r.scores[1, cols])  # still straddles its sub-boundary
        for side, (prob, vid, vp) in enumerate(zip(p["p_predicted"], p["variants"], p["variant_p_predicted"])):
            if prob >= target:
                assert vid is None
            elif vid is not None:  # the variant holds, keeps its side's mode, and its partner holds too
                v = by_id[vid]
                assert v["variant_of"] == p["scenarios"][side] and vp == v["p_predicted"] >= target
                mode = sim.uuv.simulate(range2017, np.array(v["u"])[None, :]).modes[0]
                assert ("TF", "SS", "MS", "TS")[mode] == p["modes"][side]
            else:
                assert p["verdict"] == "fragile" and f"side {'ab'[side]}: no variant found" in p["reason"]
        holds = [pr >= target or v is not None for pr, v in zip(p["p_predicted"], p["variant_p_predicted"])]
        verdict = "sharp" if min(p["p_predicted"]) >= target else "robust" if all(holds) else "fragile"
        assert p["verdict"] == verdict


def test_dither_noise_in_physical_units_becomes_a_sigma_per_coordinate(range2017):
    from planner.plan.dithering import DitherNoise

    sigma = DitherNoise.parse("position=20,time=60").sigmas(range2017)
    by_name = {n: sigma[range2017.space.slice_of(n)] for n in range2017.space.names}
    assert by_name["start_time"] == pytest.approx([60 / 43200])  # seconds over the 12-hour range
    assert by_name["tx_window_start"] == pytest.approx([60 / 600])
    assert by_name["nogo_x"] == pytest.approx([20 / 400])  # metres over the no-go area's 400 m
    assert by_name["start_battery"] == pytest.approx([0.01 / (0.4 - 0.05)])  # 1 % of capacity: the default
    assert not by_name["priority"].any()  # the plan's order is not execution noise
    unit = DitherNoise.parse("0.02").sigmas(range2017)
    keys = range2017.space.slice_of("priority")
    assert not unit[keys].any() and (np.delete(unit, np.arange(range2017.dim)[keys]) == 0.02).all()
    for spec, message in (
        ("time=300", r"^--dither-sigma: time=300.0 is 0.50 of tx_window_start's range; expected at most 0.25"),
        ("0.5", r"^--dither-sigma: a unit-cube sigma must be in \(0, 0.25\], got 0.5"),
        ("depth=3", r"^--dither-sigma: cannot read 'depth=3'"),
        ("position=-1", r"^--dither-sigma: position must be a positive number"),
    ):
        with pytest.raises(InputError, match=message):
            DitherNoise.parse(spec).sigmas(range2017)


@pytest.mark.slow
def test_generate_runs_end_to_end_on_the_chapter3_mission(tmp_path):
    """uuv18: 18 parameters, the permutation of mission-area priorities, 62 leaf scores."""
    mission = sim.uuv.load_mission(EXAMPLES / "uuv18.toml")
    plan = generate(
        mission,
        EXAMPLES / "uuv18.toml",
        tmp_path / "out",
        GenerateConfig(budget=400, batch_size=200, dithers=20, pairs=2, store=tmp_path / "study.db"),
    )
    PLAN_VALIDATOR.validate(json.loads((tmp_path / "out" / "plan.json").read_text()))
    assert len(plan["pairs"]) == 2 and plan["mission"]["name"] == mission.name
    modes = sim.uuv.simulate(mission, np.array([s["u"] for s in plan["scenarios"]])).modes
    assert [s["predicted"]["mode"] for s in plan["scenarios"]] == [("TF", "SS", "MS", "TS")[m] for m in modes]
    for p in plan["pairs"]:
        a, b = (next(s for s in plan["scenarios"] if s["id"] == sid) for sid in p["scenarios"])
        assert (
            any(a["predicted"]["scores"].get(e) != b["predicted"]["scores"].get(e) for e in p["elements"])
            or p["level"] > 1
        )  # deeper elements are not in the predicted top-level scores


def test_search_status_counts_modes_and_cross_mode_links():
    from planner.plan.search_status import SearchStatus

    status = SearchStatus(2)
    status(np.array([[0.1, 0.1], [0.9, 0.9]]), np.array([[1.0, 1.0], [0.0, 0.0]]))  # TS, TF
    assert status.links == 0 and status.modes_found == 2
    # nearest earlier runs: (0.1, 0.1) is TS -> a link for the SS run; (0.9, 0.9) is TF -> none for the TF run
    status(np.array([[0.12, 0.1], [0.88, 0.9]]), np.array([[0.0, 1.0], [0.0, 0.0]]))
    assert status.links == 1 and status.modes_found == 3
    assert status.summary() == "3 modes, 1 boundary links"


def test_a_plan_loads_from_its_embedded_mission_anywhere_and_refuses_an_edited_one(plan_dir, tmp_path, monkeypatch):
    from planner.common.plans import load_plan
    from rapt.errors import FileFormatError

    src, plan = plan_dir
    copy = tmp_path / "handed"
    shutil.copytree(src / "out", copy)
    data = json.loads((copy / "plan.json").read_text())
    data["mission"]["file"] = "examples/range2017.toml"  # relative to a directory that is not here
    (copy / "plan.json").write_text(json.dumps(data))
    monkeypatch.chdir(tmp_path)
    loaded = load_plan(copy)
    assert loaded.mission == sim.uuv.load_mission(EXAMPLES / "range2017.toml")
    assert loaded.mission_file == Path("examples/range2017.toml") and loaded.id == load_plan(src / "out").id
    edited = json.loads(json.dumps(data))
    edited["mission"]["toml"] = edited["mission"]["toml"].replace("hotel_w = 40.0", "hotel_w = 55.0", 1)
    (copy / "plan.json").write_text(json.dumps(edited))
    with pytest.raises(FileFormatError, match=r"mission\.toml was edited after the plan was generated") as err:
        load_plan(copy)
    assert "\n" not in str(err.value) and "regenerate the plan" in str(err.value)
    # a plan from before the mission was embedded: its mission file, next to plan.json, or a line saying so
    old = {**data, "mission": {k: v for k, v in data["mission"].items() if k not in ("toml", "sha256")}}
    PLAN_VALIDATOR.validate(old)  # still a rapt.plan/1 plan
    (copy / "plan.json").write_text(json.dumps(old))
    with pytest.raises(FileFormatError, match=r"not there and not embedded .* regenerate the plan$"):
        load_plan(copy)
    shutil.copy(EXAMPLES / "range2017.toml", copy / "range2017.toml")
    assert load_plan(copy).mission == loaded.mission
    half = {**data, "mission": {k: v for k, v in data["mission"].items() if k != "sha256"}}
    assert any(e.absolute_path == deque(["mission"]) for e in PLAN_VALIDATOR.iter_errors(half))


def test_a_plan_made_again_in_its_directory_leaves_no_earlier_scenario_file(tmp_path):
    from planner.plan.plan_scenarios import remove_unlisted

    for name in ("pair1a.plan", "pair1a.geojson", "pair2bM.plan", "pair2bM.waypoints", "pair2bM.csv", "notes.txt"):
        (tmp_path / name).write_text("x")
    assert remove_unlisted(tmp_path, ["pair1a", "pair1b"]) == ["pair2bM.plan", "pair2bM.waypoints"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "pair1a.geojson", "pair1a.plan", "pair2bM.csv"]
