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
from rich.measure import Measurement
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table
from rich.text import Text

__all__ = ["err", "out", "fail", "print_error", "print_table", "progress_bar"]

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


def _fit_columns(table: Table, console: Console) -> bool:
    """Fix ``table``'s column widths so it fits ``console`` with no word cut: each column at least its longest
    word, the rest of the width first to the columns that need least to show their cells on one line. False
    when even the longest words do not fit."""
    unbounded = console.options.update(width=1_000_000, max_width=1_000_000)  # Measurement.get clamps to the width
    ranges = []
    for column in table.columns:
        sizes = [Measurement.get(console, unbounded, cell) for cell in (column.header, *column.cells)]
        ranges.append((max(m.minimum for m in sizes), max(m.maximum for m in sizes)))
    overhead = Measurement.get(console, unbounded, table).maximum - sum(hi for _, hi in ranges)  # padding, rules
    room = console.width - overhead
    if sum(hi for _, hi in ranges) <= room:
        return True
    spare = room - sum(lo for lo, _ in ranges)
    if spare < 0:
        return False
    widths = [lo for lo, _ in ranges]
    for i in sorted(range(len(ranges)), key=lambda i: ranges[i][1] - ranges[i][0]):  # the short cells whole first
        give = min(spare, ranges[i][1] - ranges[i][0])
        widths[i] += give
        spare -= give
    for column, width in zip(table.columns, widths):
        column.width = width
    return True


def print_table(table: Table, console: Console = out) -> None:
    """``table`` on ``console`` as a table when every cell fits its column with no word cut or cut short;
    otherwise stacked, one block of ``header: value`` lines per row, so a narrow terminal loses no text.
    A two-column (name, value) table stays a table: only a word longer than the terminal (a path) folds."""
    for column in table.columns:  # wrap at spaces rather than cut or ellipsise
        column.no_wrap, column.overflow = False, "fold"
    if _fit_columns(table, console) or len(table.columns) <= 2:  # a name-value table gains nothing stacked
        console.print(table)
        return
    if table.title:
        console.print(table.title, style="italic", justify="center", highlight=False)
    headers = [str(c.header) for c in table.columns]
    for row in zip(*(list(c.cells) for c in table.columns)):
        block = Table.grid(padding=(0, 1))
        block.add_column(style="bold", no_wrap=True)
        block.add_column(overflow="fold")
        for header, cell in zip(headers, row):
            block.add_row(Text(f"{header}:" if header else ""), cell)
        console.print(block)
        console.print()
