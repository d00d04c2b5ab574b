"""Help text that reads as written at any terminal width: no markup, no words broken.

``rapt-plan`` prints click's plain help, not typer's rich panels: help texts name mission-file
blocks such as ``[vehicle]``, which rich markup would swallow, and click re-wraps each
paragraph to the terminal where typer's panels keep the docstrings' hard line breaks. Two
things click does not do are added here: it breaks words at their hyphens ("lock-" / "step"),
and it cuts each command's summary in the command list to one line ending in "...";
:class:`HelpFormatter` keeps hyphenated words whole and :class:`RaptGroup` lists each
command's whole summary, wrapped.
"""

from __future__ import annotations

import re
from typing import Any

import typer
import typer.core

__all__ = ["HelpFormatter", "RaptContext", "RaptCommand", "RaptGroup", "summary"]

#: A hyphen inside a word, kept unbreakable while click wraps (U+2011 NON-BREAKING HYPHEN).
_WORD_HYPHEN = re.compile(r"(?<=\w)-(?=\w)")
_NB_HYPHEN = "\u2011"


def _keep_hyphens(text: str) -> str:
    return _WORD_HYPHEN.sub(_NB_HYPHEN, text)


_ClickFormatter: Any = typer.Context.formatter_class  # click's formatter, as typer ships it


class HelpFormatter(_ClickFormatter):
    """click's formatter, with hyphenated words (``--no-stochastic``, ``lock-step``) never split across lines."""

    def write_text(self, text: str) -> None:
        super().write_text(_keep_hyphens(text))

    def write_dl(self, rows, col_max: int = 30, col_spacing: int = 2) -> None:
        super().write_dl([(a, _keep_hyphens(b)) for a, b in rows], col_max, col_spacing)

    def getvalue(self) -> str:
        return super().getvalue().replace(_NB_HYPHEN, "-")


class RaptContext(typer.Context):
    formatter_class = HelpFormatter


def summary(help_text: str | None) -> str:
    """A command's summary: the first paragraph of its help, on one line."""
    return " ".join((help_text or "").strip().split("\n\n")[0].split())


class RaptCommand(typer.core.TyperCommand):
    context_class = RaptContext


class RaptGroup(typer.core.TyperGroup):
    """The command group: its help lists every command with its whole summary, wrapped to the terminal."""

    context_class = RaptContext

    def format_commands(self, ctx, formatter) -> None:
        rows = []
        for name in self.list_commands(ctx):
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                rows.append((name, summary(cmd.help)))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)
