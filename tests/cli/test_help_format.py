"""Every command's help and the main tables read whole at 80 columns: no bracketed word swallowed, no word broken."""

import inspect
import json
import re
from pathlib import Path

import pytest
import typer
from rich.console import Console
from rich.table import Table
from typer.testing import CliRunner

from planner.cli import app
from planner.cli.console import print_table
from planner.cli.generate import summary_table
from planner.cli.help_format import summary

ROOT = Path(__file__).resolve().parents[2]
COMMANDS = [info.name for info in app.registered_commands]
runner = CliRunner()


def _flat(text: str) -> str:
    return " ".join(text.split())


def _help(args: list[str]) -> str:
    result = runner.invoke(app, [*args, "--help"], env={"COLUMNS": "80"}, terminal_width=80)
    assert result.exit_code == 0, result.output
    return result.output


def _texts(command_name: str) -> list[str]:
    """The help texts a command was written with: its docstring's paragraphs and each parameter's help."""
    info = next(i for i in app.registered_commands if i.name == command_name)
    doc = inspect.cleandoc(info.callback.__doc__ or "")
    texts = [p for p in doc.split("\n\n") if p.strip()]
    for param in inspect.signature(info.callback).parameters.values():
        for meta in getattr(param.annotation, "__metadata__", ()):
            if isinstance(meta, typer.models.ParameterInfo) and meta.help:
                texts.append(meta.help)
    return texts


@pytest.mark.parametrize("command", COMMANDS)
def test_help_keeps_every_word_and_bracket_at_80_columns(command):
    output = _help([command])
    assert max(len(line) for line in output.splitlines()) <= 80, output
    flat = _flat(output)
    texts = _texts(command)
    assert texts, command
    for text in texts:  # whole, words and brackets included, wherever the lines broke
        assert _flat(text) in flat, (command, text)
    for word in re.findall(r"\[[a-z_]+\]", " ".join(texts)):
        assert word in output, (command, word)


def test_the_bracketed_block_names_the_issue_reported_are_shown():
    assert "[vehicle]" in _help(["calibrate"])
    assert "[execution_bias]" in _help(["calibrate"])


def test_hyphenated_words_are_not_split_across_lines():
    output = _help(["run"])
    assert "lock-step" in output and "--no-stochastic" in output
    assert not re.search(r"\w-\n", output), output


def test_the_command_list_shows_each_whole_summary():
    output = _help([])
    for info in app.registered_commands:
        assert summary(info.callback.__doc__) in _flat(output), info.name
    assert not re.search(r"\w\.\.\.$", output, re.M), output  # click's cut summaries end "word..."


def _render(table: Table, width: int) -> str:
    console = Console(width=width, record=True, file=open("/dev/null", "w"))  # noqa: SIM115
    print_table(table, console)
    console.file.close()
    return console.export_text()


def _cells(plan: dict) -> list[str]:
    return [name for p in plan["pairs"] for name in p["elements"]] + [m for p in plan["pairs"] for m in p["modes"]]


@pytest.mark.parametrize("width", [80, 60, 40])
def test_the_generate_table_never_cuts_a_sub_boundary_name(width):
    plan = json.loads((ROOT / "field_plans" / "range2017" / "plan.json").read_text())
    text = _render(summary_table(plan, "range2017: field plan"), width)
    assert max(len(line.rstrip()) for line in text.splitlines()) <= width, text
    words = set(re.findall(r"[\w.%]+", text))
    for name in _cells(plan):
        assert name in words, (width, name, text)
    assert "…" not in text


def test_a_table_that_fits_stays_a_table_and_one_that_cannot_is_stacked():
    plan = json.loads((ROOT / "field_plans" / "range2017" / "plan.json").read_text())
    assert "┃ pair" in _render(summary_table(plan, "t"), 80)
    stacked = _render(summary_table(plan, "t"), 40)
    assert "┃" not in stacked
    assert stacked.count("sub-boundary:") == len(plan["pairs"])
