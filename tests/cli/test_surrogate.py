"""``rapt-plan surrogate`` and ``generate --surrogate``: train a surrogate, search with it, confirm with the expert."""

from __future__ import annotations

from pathlib import Path

import numpy as np

import sim.uuv
from sim.uuv.imitation.features import feature_spec
from sim.uuv.imitation.surrogate import Surrogate

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
IMITATION7 = sim.uuv.load_mission(EXAMPLES / "imitation7.toml")
SPEC = feature_spec(IMITATION7)


def _surrogate_args(mission: str, model: Path) -> list[str]:
    """A small, quick training run: 10 annotated and 4 held-out expert runs, 10 epochs, 16 validation scenarios."""
    options = "--runs 10 --runs-per-iteration 5 --epochs 10 --validate 16 --select-runs 4"
    return ["surrogate", mission, "--out", str(model), *options.split()]


def _generate_args(mission: str, out: Path, model: Path) -> list[str]:
    """A 500-run search on the surrogate, confirmed by at most 20 expert runs."""
    options = "--budget 500 --batch-size 250 --pairs 2 --dithers 40 --confirm-runs 20"
    return ["generate", mission, "--out", str(out), "--surrogate", str(model), *options.split()]


def test_cli_trains_a_surrogate_and_generate_searches_with_it_and_confirms_with_the_expert(tmp_path):
    import json

    from typer.testing import CliRunner

    from planner.cli import app

    runner = CliRunner()
    model = tmp_path / "imitation7.npz"
    mission = str(EXAMPLES / "imitation7.toml")
    result = runner.invoke(app, _surrogate_args(mission, model))
    assert result.exit_code == 0, result.output
    assert (
        model.is_file()
        and "mode accuracy" in result.output
        and "14 expert runs: 10 annotated + 4 held out" in result.output
    )
    policy = Surrogate.load(model, IMITATION7).policy  # the goal decision is its own network, blind to the scan
    (steer_in, steer_out, _), (goal_in, goal_out, goal) = policy.heads
    assert steer_in.size == SPEC.size and steer_out.tolist() == [0, 1, 3] and goal_out.tolist() == [2]
    assert goal.output == "decision"  # a classifier: 2 p - 1
    assert goal_in.tolist() == [0, 1, 2, 3, 4, 5, 6, SPEC.size - 1]
    out = tmp_path / "plan"
    args = _generate_args(mission, out, model)
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    plan = json.loads((out / "plan.json").read_text())
    s = plan["study"]["surrogate"]
    # the confirmation is a budget of expert runs: two at least for every candidate examined
    assert s["expert_runs"]["training"] == 14 and s["confirm_budget"] == 20
    assert 2 * s["examined"] <= s["expert_runs"]["confirmation"] <= 20 and s["examined"] <= s["candidates"] <= 10
    # every planned pair was confirmed; the ranking may still drop a confirmed pair (one boundary, two brackets)
    assert 1 <= len(plan["pairs"]) <= s["confirmed"] <= 2
    assert s["share_confirmed"] == s["confirmed"] / max(s["examined"], 1)
    assert sum(p["expert_runs"] for p in plan["pairs"]) <= s["expert_runs"]["confirmation"]
    assert f"confirmed {s['confirmed']} of {s['examined']} candidate pairs examined" in result.output
    for pair in plan["pairs"]:  # the expert's own outcome changes across every planned pair, in its elements
        assert pair["confirmed_by_expert"] and pair["moved_by"] >= 0 and pair["elements"]
        a, b = (next(sc for sc in plan["scenarios"] if sc["id"] == sid) for sid in pair["scenarios"])
        expert = sim.uuv.simulate(IMITATION7, np.array([a["u"], b["u"]]))
        assert [("TF", "SS", "MS", "TS")[m] for m in expert.modes] == pair["modes"]
        cols = [expert.names.index(e) for e in pair["elements"]]
        assert np.all(expert.scores[0, cols] != expert.scores[1, cols])
    import jsonschema

    jsonschema.validate(
        plan, json.loads((Path(__file__).resolve().parents[2] / "planner" / "plan.schema.json").read_text())
    )
    assert (out / "study-surrogate.db").is_file() and not (out / "study.db").exists()
    # a surrogate of another mission is refused in one line, exit code 2
    other = tmp_path / "other"
    result = runner.invoke(
        app,
        [
            "generate",
            str(EXAMPLES / "range2017.toml"),
            "--out",
            str(other),
            "--budget",
            "500",
            "--surrogate",
            str(model),
        ],
    )
    assert result.exit_code == 2 and "--surrogate: surrogate: trained for mission 'imitation7'" in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1
    result = runner.invoke(app, ["surrogate", mission, "--out", str(tmp_path / "x.npz"), "--method", "bogus"])
    assert result.exit_code == 2 and "--method: expected one of" in result.output
    result = runner.invoke(app, ["surrogate", mission, "--out", str(tmp_path / "x.npz"), "--observation", "sonar"])
    assert result.exit_code == 2 and "--observation: expected contacts or scan, got 'sonar'" in result.output


def test_a_corrupt_or_outdated_surrogate_file_is_refused_in_one_line(tmp_path):
    import json

    from typer.testing import CliRunner

    from planner.cli import app

    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 half a zip archive")
    old = tmp_path / "old.npz"  # a surrogate of the velocity-vector layout (format /2)
    np.savez(old, header=np.array(json.dumps({"format": "rapt.surrogate/2", "mission": "imitation7"})))
    scan = tmp_path / "scan.npz"  # the last format: a 360-degree scan with no memory of contacts
    np.savez(scan, header=np.array(json.dumps({"format": "rapt.surrogate/3", "mission": "imitation7"})))
    for path, message in (
        (junk, "is not a surrogate file"),
        (old, "observes a velocity vector on a 360-degree scan, not the expert's remembered contacts; retrain it"),
        (scan, "observes a 360-degree scan with no memory of contacts, not the expert's remembered contacts"),
    ):
        out = tmp_path / path.stem
        args = ["generate", str(EXAMPLES / "imitation7.toml"), "--out", str(out), "--surrogate", str(path)]
        result = CliRunner().invoke(app, args)
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert result.exit_code == 2 and len(lines) == 1 and message in lines[0], result.output
        assert "--surrogate" in lines[0]  # names the option to fix
    assert "not a surrogate file" not in lines[0]  # the outdated file is told to retrain, not called junk
