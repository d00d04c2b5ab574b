"""The code checks configured in pyproject.toml, run by the test command so they hold on every change.

ruff (lint and format), mypy, and import-linter's contracts for the dependency rules: planner wires
sim and bridge, which stand on rapt and never meet; the UUV world and the robots never import each
other; only the command line (and its tests) imports the command line.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rapt", "sim", "bridge", "planner", "tests")


def _tool(name: str, *args: str, cwd: Path = ROOT, env: dict | None = None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name(name)
    assert exe.exists(), f"{name} is not installed beside {sys.executable}: pip install -e '.[test]'"
    return subprocess.run([str(exe), *args], cwd=cwd, capture_output=True, text=True, timeout=300, env=env)


def _passes(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]


def test_ruff_finds_nothing_to_fix():
    _passes(_tool("ruff", "check", "--no-cache", "."))


def test_the_code_is_formatted():
    _passes(_tool("ruff", "format", "--no-cache", "--check", "."))


def test_mypy_passes():
    _passes(_tool("mypy", "--cache-dir", os.devnull))


def test_the_import_layers_hold():
    _passes(_tool("lint-imports", "--no-cache"))


@pytest.mark.parametrize(
    ("module", "forbidden", "contract"),
    [
        ("rapt/space.py", "planner", "planner wires sim and bridge"),
        ("bridge/setpoint.py", "sim.uuv", "planner wires sim and bridge"),
        ("sim/uuv/geo.py", "bridge", "planner wires sim and bridge"),
        ("sim/robots/model.py", "sim.uuv", "the simulated systems are independent"),
        ("planner/review/compare.py", "planner.cli", "only the command line"),
    ],
)
def test_the_import_check_fails_on_a_forbidden_import(tmp_path, module, forbidden, contract):
    """A copy of the tree with one forbidden import added breaks the named contract (and only then)."""
    for package in PACKAGES:
        shutil.copytree(ROOT / package, tmp_path / package, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    _passes(_tool("lint-imports", "--no-cache", cwd=tmp_path, env=env))

    path = tmp_path / module
    path.write_text(path.read_text() + f"\nimport {forbidden}  # noqa: E402, F401\n")
    proc = _tool("lint-imports", "--no-cache", cwd=tmp_path, env=env)
    assert proc.returncode != 0
    broken = [line for line in proc.stdout.splitlines() if line.endswith(" BROKEN")]
    assert len(broken) == 1 and broken[0].startswith(contract), proc.stdout
    importer = module.removesuffix(".py").replace("/", ".")
    assert f"{importer} -> {forbidden}" in proc.stdout
