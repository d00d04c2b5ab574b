"""A small plan of range2017 (2 pairs, dithered, so it records its execution noise) for the afternoon's tests."""

from __future__ import annotations

import shutil
from pathlib import Path

import sim.uuv
from planner.plan.generate import GenerateConfig, generate
from tests.support.sil_day import MISSION


def small_plan(out: Path) -> Path:
    """Generate the plan into ``out``, its study store beside it as the command line keeps it; returns ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    cfg = GenerateConfig(budget=500, batch_size=250, dithers=20, pairs=2, store=out / "study.db")
    generate(sim.uuv.load_mission(MISSION), MISSION, out, cfg)
    return out


def plan_copy(plan_dir: Path, to: Path) -> Path:
    """The plan directory's files (not its study store's journal) copied to ``to``, for a test that writes into it."""
    to.mkdir(parents=True)
    for f in plan_dir.iterdir():
        if f.is_file():
            shutil.copy(f, to / f.name)
    return to
