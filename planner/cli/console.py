"""Where the command line writes: results to stdout, progress and errors to stderr.

Every ``rapt-plan`` command reports bad input the same way — one line naming the field and
the fix, exit code 2, no traceback — so the commands share this module's :func:`fail`.
With ``RAPT_TRACEBACK=1`` in the environment, :func:`fail` called while an exception is being
handled also prints its traceback: an unexpected error (a library's RuntimeError, say) then
shows where it came from instead of only its message.
"""

from __future__ import annotations

import os
import sys
import traceback
from typing import NoReturn

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

__all__ = ["err", "out", "fail", "print_error", "progress_bar"]

err = Console(stderr=True)
out = Console()


def print_error(message: str) -> None:
    """``error: message`` on stderr, on one line; ``message`` is printed as written (brackets are not rich markup)."""
    err.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)


def fail(message: str) -> NoReturn:
    """One-line error, exit code 2, no traceback (unless ``RAPT_TRACEBACK=1``: see the module docstring)."""
    if os.environ.get("RAPT_TRACEBACK") == "1" and sys.exc_info()[0] is not None:
        traceback.print_exc(file=sys.stderr)
    print_error(message)
    raise typer.Exit(code=2)


def progress_bar(label: str) -> Progress:
    """A transient progress bar on stderr (label, bar, done/total, rate, elapsed); silent when stderr is no terminal.

    ``label`` is the first column's format, e.g. ``"{task.description:>8}"``; each task
    carries a ``rate`` field for the fourth column.
    """
    return Progress(
        TextColumn(label),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=not err.is_terminal,
    )
