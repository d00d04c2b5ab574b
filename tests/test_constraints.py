"""constraints.txt pins the install by name and version only, so the README's commands work on any machine.

A direct reference (`name @ file:///...`), a local path or a URL names a place on the machine that wrote
the file; on every other machine the install stops before a test runs (pip freeze writes such lines for a
wheel installed from a local file, which is why `.ci/pin-constraints` uses `pip list --format=freeze`).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

CONSTRAINTS = Path(__file__).resolve().parents[1] / "constraints.txt"

#: A distribution name (PEP 508) and an exact version, nothing else on the line.
PIN = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9._-]*[A-Za-z0-9])?==[A-Za-z0-9.!+_-]+")


def pin_problems(path: Path) -> list[str]:
    """Every line of a constraints file that is not a comment, a blank or a plain `name==version` pin."""
    problems = []
    names: dict[str, int] = {}
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        if not PIN.fullmatch(text):
            problems.append(f"{path.name}:{number}: {text[:100]!r} is not name==version")
            continue
        name = re.sub(r"[-_.]+", "-", text.split("==")[0]).lower()
        if name in names:
            problems.append(f"{path.name}:{number}: {name} is pinned again (line {names[name]})")
        names[name] = number
    return problems


def test_every_line_of_constraints_txt_is_a_plain_pin():
    assert CONSTRAINTS.exists()
    assert pin_problems(CONSTRAINTS) == []
    assert any(line.startswith("numpy==") for line in CONSTRAINTS.read_text().splitlines())


@pytest.mark.parametrize(
    "bad",
    [
        "websockets @ file:///tmp/fx/websockets-17.4-cp311-cp311-manylinux_2_28_x86_64.whl#sha256=cebad8f4",
        "numpy @ https://example.org/numpy-2.4.6.whl",
        "file:///tmp/fx/websockets-17.4-py3-none-any.whl",
        "/opt/wheels/torch-2.13.0+cpu-cp311-cp311-manylinux_2_28_x86_64.whl",
        "./wheels/rapt-0.1.whl",
        "https://example.org/simple/numpy/numpy-2.4.6.tar.gz",
        "git+https://example.org/rapt.git@main",
        "-e .",
        "--find-links /opt/wheels",
        "numpy>=2.4",
        "numpy",
    ],
)
def test_a_copy_with_a_line_that_is_not_a_pin_is_refused(tmp_path, bad):
    copy = tmp_path / "constraints.txt"
    lines = CONSTRAINTS.read_text().splitlines()
    copy.write_text("\n".join([*lines[:20], bad, *lines[20:]]) + "\n")
    problems = pin_problems(copy)
    assert len(problems) == 1
    assert problems[0].startswith(f"constraints.txt:21: {bad[:100]!r}")


def test_a_name_pinned_twice_is_refused(tmp_path):
    copy = tmp_path / "constraints.txt"
    copy.write_text(CONSTRAINTS.read_text() + "Typing-Extensions==4.0.0\n")
    assert [p for p in pin_problems(copy) if "pinned again" in p]
