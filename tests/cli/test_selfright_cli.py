"""``rapt-plan selfright`` through typer's CliRunner on a one-command app."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import typer
from typer.testing import CliRunner

from planner.cli.selfright import selfright

app = typer.Typer()
app.command()(selfright)
runner = CliRunner()


def doc_queries(out) -> int:
    return json.loads((out / "graph.json").read_text())["queries"]


def test_selfright_writes_graph_plots_and_report(tmp_path):
    out = tmp_path / "one"
    res = runner.invoke(app, ["examples/robots/1dof.toml", "--budget", "300", "--out", str(out), "--seed", "2"])
    assert res.exit_code == 0, res.output
    assert f"{doc_queries(out)} queries" in res.output and "self-rightable" in res.output
    doc = json.loads((out / "graph.json").read_text())
    assert doc["robot"] == "1dof" and doc["slope_deg"] == 20.0  # slope from the robot file
    assert 300 <= doc["queries"] <= 300 + 12  # whole hulls: the last one may overshoot by a few faces
    assert 0 <= doc["home_node"] < len(doc["nodes"]) and doc["nodes"][doc["home_node"]]["home"]
    assert 0.0 < doc["self_rightable_fraction"] <= 1.0
    for e in doc["edges"]:
        assert e["energy_J"] > 0 and e["source"] != e["target"]
    reach = [n for n in doc["nodes"] if n["can_right"] and not n["home"]]
    assert reach  # some region rights itself by a transition
    for n in reach:  # a righting path ends at home and its energy is the sum of its edges
        path = [doc["edges"][i] for i in n["righting_path"]]
        assert path[0]["source"] == n["id"] and path[-1]["target"] == doc["home_node"]
        assert abs(sum(p["energy_J"] for p in path) - n["energy_to_home_J"]) < 1e-3
    g = ET.parse(out / "graph.graphml").getroot()
    ns = {"g": "http://graphml.graphdrawing.org/xmlns"}
    assert len(g.findall(".//g:node", ns)) == len(doc["nodes"])
    assert len(g.findall(".//g:edge", ns)) == len(doc["edges"])
    assert (out / "states.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    report = (out / "report.md").read_text()
    assert "self-rightable fraction" in report and "states.png" in report
    # same seed, same graph
    res2 = runner.invoke(
        app, ["examples/robots/1dof.toml", "--budget", "300", "--out", str(tmp_path / "two"), "--seed", "2"]
    )
    assert res2.exit_code == 0
    assert json.loads((tmp_path / "two" / "graph.json").read_text()) == doc


def test_slope_option_overrides_the_robot_file(tmp_path):
    res = runner.invoke(app, ["examples/robots/1dof.toml", "--budget", "120", "--slope", "0", "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    assert json.loads((tmp_path / "graph.json").read_text())["slope_deg"] == 0.0


def test_outcomes_option_steers_the_search_by_where_states_tip(tmp_path):
    """--outcomes at a tenth of the 1° grid's queries and a coarse r_max: the 1-DOF graph's five regions and seven
    transitions (this seed without it: four and five, a narrow stable island stepped over)."""
    args = [
        "examples/robots/1dof.toml",
        "--budget",
        "210",
        "--r-min",
        "0.5",
        "--r-max",
        "45",
        "--batch-size",
        "10",
        "--refine",
        "0.4",
        "--seed",
        "1",
    ]
    docs = []
    for extra in ([], ["--outcomes"]):
        out = tmp_path / ("steered" if extra else "plain")
        res = runner.invoke(app, args + extra + ["--out", str(out)])
        assert res.exit_code == 0, res.output
        docs.append(json.loads((out / "graph.json").read_text()))
    plain, steered = docs
    assert steered["queries"] <= 210 + 12 and steered["self_rightable_fraction"] == 1.0
    assert len(steered["nodes"]) >= 5 and len(steered["edges"]) >= 7
    assert len(plain["nodes"]) < len(steered["nodes"]) and len(plain["edges"]) < len(steered["edges"])


def test_selfright_reads_a_urdf_robot(tmp_path):
    """The URDF twin of 1dof.toml (URDF has no slope, so --slope gives the TOML file's 20°) gives the same graph."""
    docs = []
    for robot in ("examples/robots/1dof.urdf", "examples/robots/1dof.toml"):
        out = tmp_path / robot.rsplit(".", 1)[1]
        res = runner.invoke(app, [robot, "--slope", "20", "--budget", "60", "--out", str(out)])
        assert res.exit_code == 0, res.output
        docs.append(json.loads((out / "graph.json").read_text()))
    assert docs[0] == docs[1] and docs[0]["queries"] >= 60


def test_bad_inputs_are_one_line_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[[link]]\nname = "body"\nmass = 1\nboxes = [{ size = [0.5, -1, 0.2] }]\n')
    bad_urdf = tmp_path / "bad.urdf"
    bad_urdf.write_text('<robot name="r"><link name="b"/><joint name="j" type="prismatic"/></robot>')
    cases = [
        ([str(bad)], "link[0].boxes[0].size"),
        ([str(tmp_path / "missing.toml")], "does not exist"),
        ([str(tmp_path / "robot.yaml")], "neither .toml nor .urdf"),
        ([str(bad_urdf)], "joint[@name='j']/@type"),
        (["examples/robots/1dof.toml", "--slope", "95"], "--slope"),
        (["examples/robots/1dof.toml", "--budget", "3"], "--budget"),
        (["examples/robots/1dof.toml", "--r-min", "5", "--r-max", "1"], "--r-min"),
        (["examples/robots/1dof.toml", "--refine", "1.5"], "--refine"),
    ]
    for args, field in cases:
        res = runner.invoke(app, args + ["--out", str(tmp_path / "o")])
        assert res.exit_code == 2, (args, res.output)
        assert field in res.output and "Traceback" not in res.output
        assert len([line for line in res.output.strip().splitlines() if line.strip()]) == 1
