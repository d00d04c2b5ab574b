"""rapt-plan compare: a plan flown in SIL by a biased vehicle, read back, the bias recovered, re-planned.

One small plan (2 pairs of the 2017 range mission) is generated and each scenario flown
through the whole stack — `rapt-plan run PLAN --scenario ID --inject-bias ... --log`,
real MAVLink on loopback and a real Zenoh session, two runs at a time — then compared,
together with a truncated and a corrupted copy of one log.  The other tests reuse those
logs.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

import sim.uuv
from bridge import foxglove, keys
from bridge.logger import LOSSES_METADATA, read_log
from planner.cli import app
from planner.common.plans import load_plan
from planner.review.logs import read_run
from planner.review.overlay import overlay_name
from sim.uuv.bias import Bias, parse_bias
from sim.uuv.geo import LocalFrame
from tests.support.foxglove_check import check_channel, foxglove_channels, read_with_typescript
from tests.support.sil_day import MISSION, digests, fly_plan

pytestmark = [pytest.mark.slow, pytest.mark.integration]

INJECTED = {"speed": 1.15, "current_offset": 0.3}
runner = CliRunner()


@pytest.fixture(scope="module")
def flown(tmp_path_factory):
    base = tmp_path_factory.mktemp("range_day")
    bias = ",".join(f"{k}={v}" for k, v in INJECTED.items())
    plan_dir, plan, ids, done = fly_plan(base, ["--inject-bias", bias])
    logs_dir = base / "logs"
    for sid, proc in zip(ids, done):
        assert proc.returncode == 0, (sid, proc.stdout, proc.stderr)
        row = next(line for line in proc.stdout.splitlines() if "same scores as the batch simulator" in line)
        assert "yes" in row, proc.stdout  # the SIL run equals the batch simulator under the same bias
    logs = [logs_dir / f"{sid}.mcap" for sid in ids]
    # a logger killed mid-run: the first 60 % of a log; a damaged disk: bytes overwritten mid-file
    data = logs[0].read_bytes()
    truncated = base / "killed.mcap"
    truncated.write_bytes(data[: int(len(data) * 0.6)])
    corrupt = base / "damaged.mcap"
    bad = bytearray(logs[1].read_bytes())
    with open(logs[1], "rb") as f:
        chunks = sorted(make_reader(f).get_summary().chunk_indexes, key=lambda c: c.chunk_start_offset)
    middle = chunks[len(chunks) // 2]
    at = middle.chunk_start_offset + middle.chunk_length // 2
    bad[at : at + 64] = bytes(64)  # inside one chunk's compressed records
    corrupt.write_bytes(bytes(bad))
    inputs = logs + [truncated, corrupt] + sorted(p for p in plan_dir.rglob("*") if p.is_file())
    before = digests(inputs)
    out = base / "comparison"
    result = runner.invoke(
        app,
        ["compare", str(plan_dir), *map(str, logs), str(truncated), str(corrupt), "--out", str(out), "--dithers", "5"],
    )
    assert result.exit_code == 0, result.output
    return {
        "plan_dir": plan_dir,
        "plan": plan,
        "logs": logs,
        "truncated": truncated,
        "corrupt": corrupt,
        "out": out,
        "output": result.output,
        "inputs": inputs,
        "before": before,
        "comparison": json.loads((out / "comparison.json").read_text()),
    }


def test_compare_recovers_the_injected_bias_and_corrects_the_predictions(flown):
    c = flown["comparison"]
    neutral = Bias()
    for name, value in INJECTED.items():
        est, se = c["bias"][name]["estimate"], c["bias"][name]["stderr"]
        shift = value - getattr(neutral, name)
        assert abs(est - value) <= 0.2 * abs(shift), (name, est, value)  # within 20 % of the injected bias
        assert c["bias"][name]["identified"] and se < 0.2 * abs(shift)
    for name in ("current_scale", "heading", "battery"):  # not injected: unidentified or close to neutral
        v = c["bias"][name]
        assert not v["identified"] or abs(v["estimate"] - getattr(neutral, name)) < 0.05, (name, v)
    cv = c["cross_validation"]  # checked on held-out logs before it is used
    held = cv["held_out_mode_agreement"]
    assert held["corrected"] >= 0.9 and held["corrected"] >= held["uncorrected"]
    assert c["correction"]["used"] and c["correction"]["note"].startswith("correction used")
    ag = c["mode_agreement"]
    assert ag["scenarios"] == len(flown["plan"]["scenarios"])
    assert ag["corrected"] >= 0.9 and ag["corrected"] >= ag["uncorrected"]
    for r in c["scenarios"]:
        assert {"id", "predicted_mode", "observed_mode", "path_error_m"} <= set(r)
        if r["log_complete"]:
            assert r["observed_mode"] in ("TF", "SS", "MS", "TS")
            assert r["path_error_corrected_m"] < max(r["path_error_m"], 1.0)
    assert f"{ag['corrected']:.0%} with the correction used" in flown["output"]
    assert "held-out (leave one log out) mode agreement" in flown["output"]
    html = (flown["out"] / "comparison.html").read_text()
    assert "Execution bias" in html and "Re-plan" in html
    assert len(list((flown["out"] / "figures").glob("*.png"))) >= len(c["scenarios"]) + 1


def test_pairs_are_reported_and_fragile_ones_re_planned_under_the_bias(flown):
    c = flown["comparison"]
    plan = load_plan(flown["plan_dir"])
    assert [p["id"] for p in c["pairs"]] == [p["id"] for p in plan.pairs]
    for p in c["pairs"]:
        assert p["observed_straddles"] is not None  # both sides flown to the end
        assert 0.0 <= p["p_straddles"] <= min(p["p_sides"])  # both sides at once: no likelier than either
        assert p["flagged"] == (p["p_straddles"] < c["forecast"]["straddle_below"])  # judged by the forecast
        assert p["flagged_deterministic"] == bool(p["moved_sides"])  # the single prediction's verdict beside it
        if p["flagged"]:
            assert p["reason"].startswith("straddles with P")
    for q in c["proposals"]:
        assert q["id"] == q["variant_of"] + "M"
        if q["found"]:  # under the fitted bias the adjusted scenario shows what the plan intended
            u = np.array(q["u"])
            bias = Bias(**c["correction"]["bias"])
            r = sim.uuv.simulate(plan.mission, u[None, :], bias=bias)
            for name, value in q["intended"].items():
                assert r.column(name)[0] == value


def test_truncated_and_damaged_logs_are_read_as_far_as_they_go(flown):
    c = flown["comparison"]
    rows = {r["log"]: r for r in c["scenarios"]}
    killed, damaged = rows[flown["truncated"].name], rows[flown["corrupt"].name]
    assert killed["observed_mode"] is None and not killed["log_complete"] and killed["steps"] > 100
    assert any("footer" in p for p in killed["lost"]) and any("end is not in the log" in p for p in killed["lost"])
    assert any("damaged chunk" in p for p in damaged["lost"])
    full = read_run(flown["logs"][0])
    part = read_run(flown["truncated"])
    n = part.steps.shape[0]
    assert 0 < n < full.steps.shape[0]
    np.testing.assert_array_equal(part.steps, full.steps[:n])  # what survived is exactly what was logged
    assert "warning:" in flown["output"] and flown["truncated"].name in flown["output"]


def test_compare_never_modifies_its_inputs(flown):
    assert digests(flown["inputs"]) == flown["before"]


def test_logs_name_plan_and_scenario_but_not_the_injected_bias(flown):
    plan = load_plan(flown["plan_dir"])
    run = read_run(flown["logs"][0])
    assert run.meta["plan_id"] == plan.id and run.meta["scenario_id"] == plan.scenarios[0]["id"]
    assert run.meta["mission"] == plan.mission.name
    text = json.dumps(run.meta)
    assert not any(name in text for name in ("speed", "current_offset", "bias"))


def _rewrite_meta(src: Path, dst: Path, losses: dict | None = None, **changes) -> None:
    """A copy of a log whose scenario metadata says something else (another mission or plan), without
    the logger's ``rapt.losses`` record unless ``losses`` gives one."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = make_reader(f)
        w = Writer(g)
        w.start()
        schemas, channels = {}, {}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(
                    channel.topic, channel.message_encoding, schemas.get(channel.schema_id, 0)
                )
            data = message.data
            if channel.topic.endswith("/meta/scenario"):
                obj = {**json.loads(data), **changes}
                data = json.dumps(obj).encode()
                w.add_metadata("scenario", {k: v if isinstance(v, str) else json.dumps(v) for k, v in obj.items()})
            w.add_message(channels[channel.id], log_time=message.log_time, data=data, publish_time=message.publish_time)
        if losses is not None:
            w.add_metadata(LOSSES_METADATA, {k: json.dumps(v) for k, v in losses.items()})
        w.finish()


def _without_positions(src: Path, dst: Path, share: tuple[float, float]) -> None:
    """A copy of log ``src`` whose position reports (GLOBAL_POSITION_INT, raw and decoded) between ``share`` of its
    log time are gone: a lost-position segment, every other record (metadata included) as it was."""
    from mcap.writer import Writer

    from bridge.frames import message_id
    from bridge.logger import RAW_TOPIC

    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        t0, t1 = summary.statistics.message_start_time, summary.statistics.message_end_time
        cut = (t0 + share[0] * (t1 - t0), t0 + share[1] * (t1 - t0))
        with open(dst, "wb") as out:
            w = Writer(out)
            w.start(profile="", library="test")
            schemas = {sid: w.register_schema(s.name, s.encoding, s.data) for sid, s in summary.schemas.items()}
            channels = {
                cid: w.register_channel(c.topic, c.message_encoding, schemas.get(c.schema_id, 0), dict(c.metadata))
                for cid, c in summary.channels.items()
            }
            for _, channel, m in reader.iter_messages(log_time_order=False):
                position = channel.topic.endswith("/GLOBAL_POSITION_INT") or (
                    channel.topic == RAW_TOPIC and message_id(m.data) == 33  # MAVLINK_MSG_ID_GLOBAL_POSITION_INT
                )
                if position and cut[0] <= m.log_time <= cut[1]:
                    continue
                w.add_message(channels[m.channel_id], m.log_time, m.data, m.publish_time, m.sequence)
            for record in reader.iter_metadata():
                w.add_metadata(record.name, dict(record.metadata))
            w.finish()


def test_every_run_is_checked_and_one_that_failed_is_not_fitted_unless_kept(flown, tmp_path):
    """Each log's automatic checks reach comparison.json, the table and the report; a copy of a run that lost its
    position for a tenth of the run fails its position check (`rapt-plan check` exits 1) and is left out of the
    bias fit, unless --keep-failed."""
    from planner.review.run_checks import CHECKS

    c = flown["comparison"]
    for lg in c["logs"]:
        assert [k["name"] for k in lg["checks"]] == list(CHECKS), lg["path"]
    clean = {k["name"]: k["verdict"] for k in c["logs"][0]["checks"]}
    assert "fail" not in clean.values(), c["logs"][0]["checks"]
    for name in ("estimator", "position", "link", "setpoints", "depth", "statustext", "modes"):
        assert clean[name] == "pass", c["logs"][0]["checks"]
    failed = {Path(lg["path"]).name: [k for k in lg["checks"] if k["verdict"] == "fail"] for lg in c["logs"]}
    assert not any(failed.values()), failed
    assert all(r["counted_in_bias_fit"] for r in c["scenarios"]) and not c["run_checks"]["excluded_from_bias_fit"]
    assert "Run checks" in (flown["out"] / "comparison.html").read_text()

    gapped = tmp_path / "gapped.mcap"
    _without_positions(flown["logs"][2], gapped, (0.3, 0.4))
    checked = runner.invoke(app, ["check", str(gapped)], env={"COLUMNS": "200"})
    assert checked.exit_code == 1, checked.output
    assert re.search(r"position\s+│\s+fail", checked.output), checked.output
    fast = ["--dithers", "0", "--bootstrap", "0", "--draws", "10"]
    logs = [str(p) for p in flown["logs"]] + [str(gapped)]
    out = tmp_path / "comparison"
    result = runner.invoke(app, ["compare", str(flown["plan_dir"]), *logs, "--out", str(out), *fast])
    assert result.exit_code == 0, result.output
    assert "not counted in the bias fit" in result.output and "gapped.mcap" in result.output
    comparison = json.loads((out / "comparison.json").read_text())
    assert comparison["run_checks"]["excluded_from_bias_fit"] == ["gapped.mcap"]
    [row] = [r for r in comparison["scenarios"] if r["log"] == "gapped.mcap"]
    assert row["checks"].startswith("fail: ") and "position" in row["checks"] and not row["counted_in_bias_fit"]
    channels = foxglove_channels(out / overlay_name(row["id"]))
    lines = [m["message"] for m in channels["/checks"].messages if m["name"] == "gapped"]
    assert any(line.startswith("position fail:") for line in lines), lines
    kept = runner.invoke(
        app, ["compare", str(flown["plan_dir"]), *logs, "--out", str(tmp_path / "kept"), *fast, "--keep-failed"]
    )
    assert kept.exit_code == 0, kept.output
    assert not json.loads((tmp_path / "kept" / "comparison.json").read_text())["run_checks"]["excluded_from_bias_fit"]


def test_each_log_says_how_many_frames_were_lost_on_the_way(flown, tmp_path):
    entries = {Path(lg["path"]).name: lg for lg in flown["comparison"]["logs"]}
    for log in flown["logs"]:  # flown in SIL through the bridge and the logger: nothing lost, and it says so
        losses = entries[log.name]["losses"]
        assert entries[log.name]["frames_lost"] == 0 and losses["link_lost"] == 0 and losses["bus_lost"] == 0
    assert entries[flown["truncated"].name]["frames_lost"] == "unknown"  # killed before the record was written
    assert "frames" in flown["output"]  # the table's "frames lost" column (rich may wrap its header)
    old, lossy = tmp_path / "old.mcap", tmp_path / "lossy.mcap"
    _rewrite_meta(flown["logs"][0], old)  # a logger from before the record
    _rewrite_meta(flown["logs"][0], lossy, losses={"total": 7, "link_lost": 5, "bus_lost": 2, "write_errors": 0})
    assert read_run(old).frames_lost == "unknown" and read_run(old).losses is None
    assert read_run(lossy).frames_lost == 7 and read_run(lossy).losses["bus_lost"] == 2


def test_a_log_of_another_mission_or_plan_is_one_line_and_exit_2(flown, tmp_path):
    other_mission = tmp_path / "imitation.mcap"
    _rewrite_meta(flown["logs"][0], other_mission, mission="imitation7")
    other_plan = tmp_path / "otherplan.mcap"
    _rewrite_meta(flown["logs"][0], other_plan, plan_id="0123456789ab")
    not_mcap = tmp_path / "notes.mcap"
    not_mcap.write_text("range day notes, not a log\n")
    for log, expect in [
        (other_mission, "was flown on mission 'imitation7'"),
        (other_plan, "flew plan 0123456789ab"),
        (not_mcap, "is not an MCAP file"),
        (tmp_path / "missing.mcap", "does not exist"),
    ]:
        result = runner.invoke(
            app, ["compare", str(flown["plan_dir"]), str(flown["logs"][1]), str(log), "--out", str(tmp_path / "cmp")]
        )
        assert result.exit_code == 2, (log, result.output)
        assert expect in result.output and "Traceback" not in result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1, result.output
    assert not (tmp_path / "cmp" / "comparison.json").exists()


def test_an_out_that_would_overwrite_an_input_fails_first_in_one_line(tmp_path, monkeypatch):
    """Refused before the plan is loaded, a log read or a run simulated, and nothing is written."""
    import planner.review.compare as compare_module

    def no_work(*args, **kwargs):
        raise AssertionError("compare did work before checking --out")

    monkeypatch.setattr(compare_module, "load_plan", no_work)
    monkeypatch.setattr(compare_module, "read_run", no_work)
    monkeypatch.setattr(sim.uuv, "simulate", no_work)
    out = tmp_path / "cmp"
    out.mkdir()
    log = out / "comparison.json"  # a log kept where the comparison would go
    log.write_text("not really a log\n")
    result = runner.invoke(app, ["compare", str(tmp_path / "plan"), str(log), "--out", str(out)])
    assert result.exit_code == 2, result.output
    assert "--out:" in result.output and "would overwrite an input" in result.output
    assert "Traceback" not in result.output
    assert len([line for line in result.output.splitlines() if line.strip()]) == 1, result.output
    assert log.read_text() == "not really a log\n" and sorted(out.iterdir()) == [log]
    log.unlink()
    kept = out / overlay_name("pair1a")  # a log kept under the name of a Foxglove overlay
    kept.write_text("not really a log\n")
    result = runner.invoke(app, ["compare", str(tmp_path / "plan"), str(kept), "--out", str(out)])
    assert result.exit_code == 2 and "would overwrite an input (an overlay_*.mcap)" in result.output, result.output
    assert kept.read_text() == "not really a log\n" and sorted(out.iterdir()) == [kept]


def test_inject_bias_on_the_command_line(flown):
    plan_json = str(flown["plan_dir"] / "plan.json")
    assert parse_bias(" speed=1.15, current_offset=0.3 ") == Bias(speed=1.15, current_offset=0.3)
    assert parse_bias("none") == Bias() and str(Bias(battery=1.1)) == "battery=1.1"
    for args, expect in [
        (["--scenario", "pair1a", "--inject-bias", "speeed=1.1"], "--inject-bias: speeed: unknown"),
        (["--scenario", "pair9z"], "--scenario: 'pair9z' is not a scenario of"),
    ]:
        result = runner.invoke(app, ["run", plan_json, *args])
        assert result.exit_code == 2 and expect in result.output, result.output
        assert len([line for line in result.output.splitlines() if line.strip()]) == 1


def test_a_calibrated_vehicle_is_flown_in_every_prediction_beside_the_plan(flown, tmp_path):
    text = MISSION.read_text()
    hungry = tmp_path / "calibrated.toml"
    hungry.write_text(text.replace("hotel_w = 40.0", "hotel_w = 55.0", 1))
    out = tmp_path / "cmp"
    result = runner.invoke(
        app,
        ["compare", str(flown["plan_dir"]), *map(str, flown["logs"][:2]), "--calibrated", str(hungry)]
        + ["--out", str(out), "--dithers", "0", "--bootstrap", "0"],
    )
    assert result.exit_code == 0, result.output
    c = json.loads((out / "comparison.json").read_text())
    assert c["calibrated_vehicle"]["hotel_w"] == 55.0
    plan = load_plan(flown["plan_dir"])
    vehicle = sim.uuv.load_mission(hungry).vehicle
    for r in c["scenarios"]:  # the plan's autonomy, flying the calibrated vehicle
        expect = sim.uuv.simulate(plan.mission, plan.u(r["id"])[None, :], plant=vehicle)
        assert r["calibrated_mode"] == ("TF", "SS", "MS", "TS")[int(expect.modes[0])]
        assert r["path_error_calibrated_m"] is not None
    assert c["mode_agreement"]["calibrated"] is not None
    assert "calibrated vehicle" in (out / "comparison.html").read_text()
    other = tmp_path / "other.toml"
    other.write_text(text.replace('name = "range2017"', 'name = "elsewhere"', 1))
    assert 'name = "elsewhere"' in other.read_text()
    bad = runner.invoke(
        app, ["compare", str(flown["plan_dir"]), str(flown["logs"][0]), "--calibrated", str(other), "--out", str(out)]
    )
    assert bad.exit_code == 2 and "--calibrated:" in bad.output and "'elsewhere'" in bad.output
    assert len([line for line in bad.output.splitlines() if line.strip()]) == 1, bad.output


def _hand_over(flown, to: Path) -> tuple[Path, list[Path]]:
    """The plan directory and two logs copied to ``to``, the plan naming its mission by the relative path
    ``rapt-plan generate examples/range2017.toml`` records (which exists only under the repository)."""
    import shutil

    plan_dir = to / "plan"
    shutil.copytree(flown["plan_dir"], plan_dir)
    data = json.loads((plan_dir / "plan.json").read_text())
    data["mission"]["file"] = "examples/range2017.toml"
    (plan_dir / "plan.json").write_text(json.dumps(data, indent=2))
    (to / "logs").mkdir()
    logs = [Path(shutil.copy2(p, to / "logs")) for p in flown["logs"][:2]]
    return plan_dir, logs


def test_a_plan_directory_compares_and_flies_from_any_directory(flown, tmp_path):
    """Only the plan directory and logs at hand (an empty tree), run from another directory."""
    import subprocess

    from tests.support.sil_day import rapt_plan

    plan_dir, logs = _hand_over(flown, tmp_path / "handed")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    assert not (elsewhere / "examples").exists()
    env = {**os.environ, "COLUMNS": "200"}

    def cli(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(rapt_plan() + list(args), cwd=elsewhere, capture_output=True, text=True, env=env)

    done = cli("compare", str(plan_dir), *map(str, logs), "--out", "cmp", "--dithers", "0", "--bootstrap", "0")
    assert done.returncode == 0, done.stderr
    c = json.loads((elsewhere / "cmp" / "comparison.json").read_text())
    assert c["plan"]["id"] == load_plan(flown["plan_dir"]).id and len(c["scenarios"]) == 2
    assert c["plan"]["mission_file"] == "examples/range2017.toml"  # recorded, not read
    flew = cli("run", str(plan_dir / "plan.json"), "--scenario", flown["plan"]["scenarios"][0]["id"])
    assert flew.returncode == 0, flew.stderr
    assert re.search(r"same scores as the batch simulator\s+│\s+yes", flew.stdout), flew.stdout


def test_an_edited_embedded_mission_is_refused_in_one_line_and_nothing_is_written(flown, tmp_path):
    plan_dir, logs = _hand_over(flown, tmp_path)
    data = json.loads((plan_dir / "plan.json").read_text())
    data["mission"]["toml"] = data["mission"]["toml"].replace("hotel_w = 40.0", "hotel_w = 55.0", 1)
    assert "hotel_w = 55.0" in data["mission"]["toml"]
    (plan_dir / "plan.json").write_text(json.dumps(data, indent=2))
    inputs = sorted(p for p in tmp_path.rglob("*") if p.is_file())
    before = digests(inputs)
    out = tmp_path / "cmp"
    for args in (
        ["compare", str(plan_dir), *map(str, logs), "--out", str(out)],
        ["run", str(plan_dir), "--scenario", "pair1a", "--log", str(tmp_path / "pair1a.mcap")],
        ["frontseat", str(plan_dir), "--scenario", "pair1a", "--mavlink", "udpin:127.0.0.1:9"],
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 2, (args, result.output)
        lines = [line for line in result.output.splitlines() if line.strip()]
        assert len(lines) == 1 and "Traceback" not in result.output, result.output
        assert "mission.toml was edited after the plan was generated" in lines[0]
        assert "regenerate the plan" in lines[0]
    assert sorted(p for p in tmp_path.rglob("*") if p.is_file()) == inputs and digests(inputs) == before
    assert not out.exists()


def test_run_logs_have_foxglove_channels_the_typescript_reader_decodes(flown):
    """A log of `rapt-plan run`: Foxglove's well-known channels beside the MAVLink ones, Protobuf under the
    Foxglove SDK's schemas (Python reader), and read back by Foxglove's TypeScript reader from npm with the
    same content."""
    log = flown["logs"][0]
    channels = foxglove_channels(log)
    expected = {
        foxglove.FIX_TOPIC: "foxglove.LocationFix",
        foxglove.LOG_TOPIC: "foxglove.Log",
        foxglove.TF_TOPIC: "foxglove.FrameTransform",
        foxglove.TRAIL_TOPIC: "foxglove.PosesInFrame",
        "/map/scenario": "foxglove.GeoJSON",
    }
    assert {t: c.schema_name for t, c in channels.items()} == expected
    for channel in channels.values():
        check_channel(channel)
    # one fix per GLOBAL_POSITION_INT, its position in degrees
    gpi = [m for t, _, m in read_log(log) if t == keys.telemetry("uuv1", "GLOBAL_POSITION_INT")]
    fixes = channels[foxglove.FIX_TOPIC].messages
    assert len(fixes) == len(gpi) > 100
    assert [(f["latitude"], f["longitude"]) for f in fixes] == [(g["lat"] / 1e7, g["lon"] / 1e7) for g in gpi]
    # the map: the scenario's elements and the plan's predicted track, once
    run = read_run(log)
    [doc] = [json.loads(m["geojson"]) for m in channels["/map/scenario"].messages]
    kinds = [f["properties"]["kind"] for f in doc["features"]]
    assert {"launch", "recovery", "operational_area", "mission_area", "nogo", "predicted_track"} <= set(kinds)
    plan = load_plan(flown["plan_dir"])
    predicted = sim.uuv.simulate(plan.mission, np.array([run.meta["u"]], dtype=float), trajectories=True)
    [line] = [f for f in doc["features"] if f["properties"]["kind"] == "predicted_track"]
    assert len(line["geometry"]["coordinates"]) == predicted.trajectory(0).shape[0]
    events = [m["message"] for m in channels[foxglove.LOG_TOPIC].messages]
    goals = [e for e in events if e.startswith("goal: ")]  # the vehicle's own STATUSTEXT interleave by timing
    assert goals[0] == "goal: waypoint" and f"run ended: {run.ended}" in events

    ts = read_with_typescript(log, foxglove.FIX_TOPIC, "/map/scenario")
    for topic, name in expected.items():
        got = ts["channels"][topic]
        assert (got["schema"], got["schemaEncoding"], got["messageEncoding"]) == (name, "protobuf", "protobuf")
        assert got["messages"] == len(channels[topic].messages)
    first = ts["first"][foxglove.FIX_TOPIC]  # protobufjs's view of the same message
    assert first["timestamp"] == {"seconds": fixes[0]["timestamp"]["sec"], "nanos": fixes[0]["timestamp"]["nsec"]}
    assert {k: first[k] for k in ("frame_id", "latitude", "longitude", "altitude", "position_covariance")} == {
        k: fixes[0][k] for k in ("frame_id", "latitude", "longitude", "altitude", "position_covariance")
    }
    assert json.loads(ts["first"]["/map/scenario"]["geojson"]) == doc
    assert ts["statisticsMessageCount"] == sum(c["messages"] for c in ts["channels"].values())
    print({t: (c["schema"], c["messages"]) for t, c in ts["channels"].items() if t in expected}, fixes[0])


def test_compare_writes_a_foxglove_overlay_per_flown_scenario(flown):
    """Next to comparison.json: per flown scenario the observed runs, the prediction and the corrected
    prediction as GeoJSON lines and LocationFix series on their own topics."""
    c = flown["comparison"]
    rows = {r["log"]: r for r in c["scenarios"]}
    assert c["overlays"] == {sid: overlay_name(sid) for sid in dict.fromkeys(r["id"] for r in c["scenarios"])}
    log = flown["logs"][0]
    sid = rows[log.name]["id"]
    path = flown["out"] / c["overlays"][sid]
    channels = foxglove_channels(path)
    for channel in channels.values():
        check_channel(channel)
    observed = [run.stem for run in (log, flown["truncated"]) if rows[run.name]["id"] == sid]
    assert observed == [log.stem, "killed"]  # the killed logger's copy of the same run
    assert set(channels) - {"/checks"} == {"/map/scenario", "/map/observed", "/map/predicted", "/map/corrected"} | {
        f"/fix/{k}" for k in ("predicted", "corrected", *(f"observed/{n}" for n in observed))
    }
    lines = {
        t: json.loads(ch.messages[0]["geojson"])["features"] for t, ch in channels.items() if t.startswith("/map/")
    }
    assert [f["properties"]["name"] for f in lines["/map/observed"]] == observed
    [corrected], [predicted] = lines["/map/corrected"], lines["/map/predicted"]
    assert corrected["properties"]["correction_used"] is c["correction"]["used"] is True
    assert corrected["geometry"]["coordinates"] != predicted["geometry"]["coordinates"]  # the fitted bias moved it
    track = read_run(log).track
    fixes = channels[f"/fix/observed/{log.stem}"].messages
    assert len(fixes) == track.shape[0]
    plan = load_plan(flown["plan_dir"])
    lat, lon = LocalFrame(plan.mission.origin_lat, plan.mission.origin_lon).to_latlon(track[-1, 1], track[-1, 2])
    assert (fixes[-1]["latitude"], fixes[-1]["longitude"]) == pytest.approx((lat, lon), abs=1e-9)
    assert fixes[-1]["timestamp"]["sec"] == int(track[-1, 0])  # log time is scenario time
    ts = read_with_typescript(path)
    assert {t: (v["schema"], v["messages"]) for t, v in ts["channels"].items()} == {
        t: (ch.schema_name, len(ch.messages)) for t, ch in channels.items()
    }


def test_the_corrected_forecast_says_how_sure_it_is_and_scores_no_worse_than_the_plan(flown):
    """Per run the mode probabilities under the plan's noise, alone and with the fitted bias's uncertainty;
    the day's Brier score of the corrected forecast no worse than the plan's single prediction's."""
    c = flown["comparison"]
    fc = c["forecast"]
    assert fc["draws"] == 100 and fc["corrected_is"] == "bias_noise"  # the correction is used (test above)
    assert set(fc["bias_varied"]) >= set(INJECTED)  # the identified parameters are drawn
    for r in c["scenarios"]:
        for name in ("noise", "bias_noise"):
            dist = r["forecast"]["modes"][name]
            assert set(dist) == {"TF", "SS", "MS", "TS"} and sum(dist.values()) == pytest.approx(1.0)
        if r["observed_mode"] is not None:
            p = r["forecast"]["p_observed_mode"]
            assert p["corrected"] == p["bias_noise"] == r["forecast"]["modes"]["bias_noise"][r["observed_mode"]]
    b = fc["brier"]
    assert b["runs"] == sum(r["observed_mode"] is not None for r in c["scenarios"])
    assert b["corrected"] == b["bias_noise"]
    # this SIL day flies every scenario exactly as planned (no start, position or timing slip), so the corrected
    # single prediction is exact here and a forecast that allows for the plan's execution noise cannot beat it;
    # it must beat the plan's own prediction and the forecast without the bias (tests/planner/review/
    # test_forecast.py flies a day with execution noise, where it beats the corrected single prediction too)
    for kind in ("mode", "held"):
        assert b["corrected"][kind] <= b["deterministic_uncorrected"][kind], b
        assert b["corrected"][kind] <= b["noise"][kind], b
    assert "Brier" in flown["output"] and "bias+noise" in flown["output"]
    assert "How sure were the predictions?" in (flown["out"] / "comparison.html").read_text()
