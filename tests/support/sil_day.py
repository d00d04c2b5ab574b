"""A small range day in lock-step SIL for the CLI tests: a 2-pair plan of range2017, every scenario flown.

``rapt-plan run PLAN --scenario ID --log`` per scenario, real MAVLink on loopback and a real
Zenoh session, two runs at a time (CI has two cores).  Shared by the compare and calibrate
tests, each with its own run options.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import sim.uuv
from planner.plan.generate import GenerateConfig, generate

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "examples" / "range2017.toml"


def rapt_plan() -> list[str]:
    exe = Path(sys.executable).with_name("rapt-plan")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "planner.cli"]


def digests(paths) -> dict[str, str]:
    return {str(p): hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths}


def fly_plan(
    base: Path, run_options: list[str], mission_file: Path = MISSION
) -> tuple[Path, dict, list[str], list[subprocess.CompletedProcess]]:
    """Generate the plan of ``mission_file`` in ``base/plan`` and fly each scenario to ``base/logs/ID.mcap``
    with ``run_options``: (plan directory, plan, scenario ids, the finished ``rapt-plan run`` processes)."""
    plan_dir = base / "plan"
    plan = generate(
        sim.uuv.load_mission(mission_file),
        mission_file,
        plan_dir,
        GenerateConfig(budget=500, batch_size=250, dithers=0, pairs=2, seed=0),
    )
    logs_dir = base / "logs"
    logs_dir.mkdir()
    ids = [s["id"] for s in plan["scenarios"]]

    def fly(sid: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            rapt_plan()
            + ["run", str(plan_dir / "plan.json"), "--scenario", sid, "--log", str(logs_dir / f"{sid}.mcap")]
            + ["--timeout", "240", *run_options],
            capture_output=True,
            text=True,
            timeout=300,
            cwd=ROOT,
            env={**os.environ, "COLUMNS": "200"},
        )

    with ThreadPoolExecutor(max_workers=2) as pool:
        done = list(pool.map(fly, ids))
    return plan_dir, plan, ids, done
