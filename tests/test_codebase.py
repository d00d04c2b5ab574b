"""The code checks, run by the test command so they hold on every change.

ruff (lint and format), mypy, and import-linter's contracts for the dependency rules (pyproject.toml):
planner wires sim and bridge, which stand on rapt and never meet; the stages of the range day (plan,
fly, review) share only planner.common; the UUV world and the robots never import each other; only
the command line (and its tests) imports the command line. Beside them, two checks of our own: no
import circle anywhere (imports inside functions and under TYPE_CHECKING count), and the size limits
that keep a function readable on one screen and a module about one concept.
"""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("rapt", "sim", "bridge", "planner", "tests")
CHECKED = (*PACKAGES, "benchmarks")

#: The longest a function body may be (from its first statement after the docstring to its last line).
MAX_FUNCTION_LINES = 80
#: The longest a module may be.
MAX_MODULE_LINES = 600


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
        ("tests/planner/review/test_biasfit.py", "planner.cli", "only the command line"),
        ("planner/review/logs.py", "planner.fly", "the range day's stages"),
        ("planner/common/plans.py", "planner.plan", "the range day's stages"),
        ("bridge/link.py", "bridge.relay", "the bridge's layers"),
        ("planner/fly/vehicle/watchdog.py", "planner.fly.sil.loop", "the SIL flight and the run on a vehicle"),
        ("sim/uuv/simulate.py", "sim.uuv.ardusub.frontseat", "the batch simulator never imports the front-seat"),
        ("sim/robots/planar.py", "sim.robots.stability", "robot files over the model"),
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


def test_the_front_seat_contract_names_every_batch_module():
    """A new module of the batch simulator is held apart from the front-seat too, not only the ones listed today."""
    import tomllib

    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    (listed,) = [c["source_modules"] for c in contracts if c["name"].startswith("the batch simulator")]
    uuv = ROOT / "sim" / "uuv"
    batch = {f"sim.uuv.{p.stem}" for p in uuv.glob("*.py") if p.stem != "__init__"}
    batch |= {f"sim.uuv.{p.parent.name}" for p in uuv.glob("*/__init__.py") if p.parent.name != "ardusub"}
    assert sorted(listed) == sorted(batch)


def _python_files() -> list[Path]:
    return sorted(p for top in CHECKED for p in (ROOT / top).rglob("*.py") if "node_modules" not in p.parts)


def _body_lines(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    body = node.body
    if len(body) > 1 and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]  # the docstring says why; it does not count
    return (node.end_lineno or node.lineno) - body[0].lineno + 1


def test_functions_and_modules_stay_short():
    """Every function body fits in MAX_FUNCTION_LINES and every module in MAX_MODULE_LINES, tests and benchmarks too."""
    over = []
    for path in _python_files():
        rel = path.relative_to(ROOT).as_posix()
        text = path.read_text()
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES:
            over.append(f"{rel}: {lines} lines (limit {MAX_MODULE_LINES}): split it at a seam")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and _body_lines(node) > MAX_FUNCTION_LINES:
                over.append(f"{rel}:{node.lineno} {node.name}: {_body_lines(node)} lines (limit {MAX_FUNCTION_LINES})")
    assert not over, "\n".join(over)


def _circles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def _package_imports() -> dict[str, set[str]]:
    """Every import between our modules, those inside functions and under TYPE_CHECKING included (grimp)."""
    import grimp

    graph = grimp.build_graph("rapt", "sim", "bridge", "planner", cache_dir=None)
    return {m: set(graph.find_modules_directly_imported_by(m)) for m in graph.modules}


def _benchmark_imports() -> dict[str, set[str]]:
    """The benchmark scripts import each other as top-level modules (each puts its folder on sys.path)."""
    scripts = {p.stem: p for p in (ROOT / "benchmarks").glob("*.py")}
    edges: dict[str, set[str]] = {}
    for name, path in scripts.items():
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module]
            edges.setdefault(name, set()).update(n.split(".")[0] for n in names if n.split(".")[0] in scripts)
    return edges


def test_no_import_circles():
    """No module imports, however indirectly, a module that imports it back."""
    circles = _circles(_package_imports()) + _circles(_benchmark_imports())
    assert not circles, "import circles: " + "; ".join(" <-> ".join(c) for c in circles)


def test_the_circle_check_finds_a_circle():
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _circles({"a": {"b"}, "b": set()}) == []
