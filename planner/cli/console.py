"""Where the command line writes: results to stdout, progress and errors to stderr.

Every ``rapt-plan`` command reports bad input the same way — one line naming the field and
the fix, exit code 2, no traceback — so the commands share this module's :func:`fail`.
"""

from __future__ import annotations

import typer
from rich.console import Console
from rich.markup import escape

__all__ = ["err", "out", "fail"]

err = Console(stderr=True)
out = Console()


def fail(message: str) -> None:
    """One-line error, exit code 2, no traceback.  ``message`` is printed as written (brackets are not rich markup)."""
    err.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code=2)
