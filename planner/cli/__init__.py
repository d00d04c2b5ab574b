"""``rapt-plan``: the test engineer's command line.

``rapt-plan study MISSION`` searches a mission file's scenario space with the simulator
and reports the performance modes and boundary types it found, side by side with a
space-filling design (Figure 3.12).  ``rapt-plan search SYSTEM`` does the same on a
bundled synthetic system with known boundaries and prints how well it found them.

Each command group is a module of this package (argument parsing, progress and printing
only); the work is done by the application modules of :mod:`planner`.
"""

from __future__ import annotations

import typer

from planner.cli import (
    bus_keys,
    calibrate,
    check,
    compare,
    generate,
    next_run,
    processes,
    run,
    search,
    selfright,
    shakedown,
    surrogate,
)
from planner.cli.console import print_error
from planner.cli.help_format import RaptCommand, RaptGroup
from rapt.errors import RaptError

__all__ = ["app", "rapt_plan"]

app = typer.Typer(
    cls=RaptGroup,
    no_args_is_help=True,
    add_completion=False,
    # click's plain help: brackets ([vehicle]) are text, paragraphs wrap to the terminal (planner.cli.help_format)
    rich_markup_mode=None,
    help="Plan field tests of autonomous underwater vehicles from adaptive boundary searches.",
)


@app.callback()
def main() -> None:
    """Plan field tests of autonomous underwater vehicles from adaptive boundary searches."""


# in this order in --help
app.command("search", cls=RaptCommand)(search.search)
app.command("study", cls=RaptCommand)(search.study)
app.command("run", cls=RaptCommand)(run.run)
app.command("generate", cls=RaptCommand)(generate.generate)
app.command("shakedown", cls=RaptCommand)(shakedown.shakedown)
app.command("surrogate", cls=RaptCommand)(surrogate.surrogate)
app.command("compare", cls=RaptCommand)(compare.compare)
app.command("next", cls=RaptCommand)(next_run.next_run)
app.command("calibrate", cls=RaptCommand)(calibrate.calibrate)
app.command("check", cls=RaptCommand)(check.check)
app.command("frontseat", cls=RaptCommand)(processes.frontseat)
app.command("bridge", cls=RaptCommand)(processes.bridge)
app.command("autonomy", cls=RaptCommand)(processes.autonomy)
app.command("log", cls=RaptCommand)(processes.log)
app.command("bus-keys", cls=RaptCommand)(bus_keys.bus_keys)
# Chapter 5's second system under test: self-righting ground robots (planner/selfright/).
app.command("selfright", cls=RaptCommand)(selfright.selfright)


def rapt_plan() -> None:
    """The ``rapt-plan`` script: the app, where a :class:`~rapt.errors.RaptError` that no command turned into its
    one-line error still ends as one (``error: ...``, exit code 2) rather than a traceback."""
    try:
        app()
    except RaptError as exc:
        print_error(str(exc))
        raise SystemExit(2) from None
