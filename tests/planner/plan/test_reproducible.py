"""The same plan under other CPU paths: NumPy's dispatch without AVX-512, another OpenBLAS kernel and glibc's libm
as on a CPU without FMA give the same pairs, scenario parameters, verdicts, P values and predicted modes; plan.json
names the runtime that made it."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from planner.plan.runtime import numerical_runtime

ROOT = Path(__file__).resolve().parents[3]
MISSION = ROOT / "examples" / "range2017.toml"
#: NumPy's dispatch targets above AVX2 (NumPy 2.x names), turned off; OpenBLAS told to use its Haswell kernels
SETTINGS = {
    "as installed": {},
    "no AVX-512 in NumPy": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "OpenBLAS Haswell": {"OPENBLAS_CORETYPE": "Haswell"},
    # glibc's libm picks its exp, log, sin, pow... by CPU; without FMA and AVX2 it takes an older CPU's paths,
    # whose last bits differ (checked below): another machine's maths, on this one
    "libm of a CPU without FMA": {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-AVX512VL"},
}
#: Last bits of libm's results for a fixed set of inputs.
LIBM_PROBE = "import math, hashlib; print(hashlib.sha1(repr([math.exp(x / 7.3) for x in range(-4000, 4000)]).encode()).hexdigest())"


def _plan(out: Path, env: dict) -> dict:
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "planner.cli",
            "generate",
            str(MISSION),
            "--out",
            str(out),
            "--budget",
            "1200",
            "--dithers",
            "400",
        ],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads((out / "plan.json").read_text())


@pytest.mark.slow  # four searches of 1,200 runs, about a minute each on 2 cores
def test_the_plan_is_the_same_under_other_numpy_dispatch_and_blas_kernels(tmp_path):
    plans = {name: _plan(tmp_path / f"plan{k}", env) for k, (name, env) in enumerate(SETTINGS.items())}
    reference = plans["as installed"]
    assert reference["runtime"]["numpy"] and reference["runtime"]["blas"]
    for name, plan in plans.items():
        # everything but the runtime record, to the last digit
        assert {k: v for k, v in plan.items() if k != "runtime"} == {
            k: v for k, v in reference.items() if k != "runtime"
        }, name
    # the settings took: NumPy reports the AVX-512 targets off, and libm's last bits moved (on a CPU with FMA)
    off = plans["no AVX-512 in NumPy"]["runtime"]["numpy_dispatch"]
    assert "X86_V4" not in off
    if " fma " in Path("/proc/cpuinfo").read_text():
        probes = [
            subprocess.run([sys.executable, "-c", LIBM_PROBE], env={**os.environ, **env}, capture_output=True).stdout
            for env in ({}, SETTINGS["libm of a CPU without FMA"])
        ]
        assert probes[0] != probes[1]


def test_the_runtime_names_the_libraries_the_blas_and_the_cpu_paths():
    runtime = numerical_runtime()
    assert {"python", "numpy", "scipy", "scikit-learn", "blas", "numpy_dispatch"} <= set(runtime)
    assert runtime["blas"] and all(b["internal_api"] for b in runtime["blas"])
    assert json.loads(json.dumps(runtime)) == runtime  # plain JSON, as plan.json stores it


#: The packages whose numbers reach plan.json.
PLAN_PACKAGES = ("rapt", "planner/plan", "planner/common")


def _vector_norms(source: str) -> list[int]:
    """Lines of ``np.linalg.norm`` calls without ``axis``: on a vector that is BLAS's nrm2, whose last bit
    depends on the kernel OpenBLAS picks for the CPU (a plan's pair distances differed by one ulp under
    OPENBLAS_CORETYPE=Haswell). ``math.dist`` and ``math.hypot`` are the same on every machine."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "norm":
            owner = node.func.value
            if isinstance(owner, ast.Attribute) and owner.attr == "linalg":
                if not any(k.arg == "axis" for k in node.keywords):
                    out.append(node.lineno)
    return out


def test_no_blas_vector_norm_reaches_the_plan():
    found = [
        f"{path.relative_to(ROOT)}:{line}"
        for package in PLAN_PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
        for line in _vector_norms(path.read_text(encoding="utf-8"))
    ]
    assert not found, f"np.linalg.norm of a vector (BLAS nrm2) in the plan's numbers; use math.dist: {found}"
    assert _vector_norms("import numpy as np\nd = np.linalg.norm(a - b)\nr = np.linalg.norm(X, axis=1)\n") == [2]
