"""``rapt-plan bus-keys DIR --vehicle NAME``: make a range's keys for the secure bus, and say where each goes."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from planner.cli.console import fail, out
from rapt.errors import InputError

__all__ = ["bus_keys"]

#: Where each role's files go on a range (printed after the keys are made).
_WHERE = {
    "ca": "ca.pem on every computer of the bus; ca.key stays with the range administrator, off the vehicle",
    "bridge": "the vehicle's companion computer (the hub: it listens and holds the access rules)",
    "watchdog": "the computer running the watchdog (usually the companion computer)",
    "logger": "the computer writing the MCAP log",
    "operator": "the operator's topside laptop",
}


def bus_keys(
    directory: Annotated[Path, typer.Argument(metavar="DIR", help="New directory to write the keys into.")],
    vehicle: Annotated[str, typer.Option("--vehicle", help="Vehicle name on the bus.")],
    hub: Annotated[
        str, typer.Option("--hub", help="The bridge's TLS endpoint, tls/HOST:PORT; clients connect to it.")
    ] = "tls/127.0.0.1:7448",
    autonomy: Annotated[
        list[str],
        typer.Option("--autonomy", help="Name of an autonomy (its set-points' source); repeat for several."),
    ] = ["autonomy"],
    days: Annotated[int, typer.Option("--days", help="Days the certificates stay valid.")] = 365,
    force: Annotated[bool, typer.Option("--force", help="Replace the keys in an existing DIR.")] = False,
) -> None:
    """Make a range CA and one key, certificate and Zenoh config per role (mutual TLS, access rules on the hub)."""
    from bridge.range_keys import make_range_keys, role_names

    try:
        path = make_range_keys(directory, vehicle, hub=hub, autonomies=autonomy, valid_days=days, force=force)
    except InputError as exc:
        fail(str(exc))
    out.print(
        f"range keys for vehicle {vehicle!r}, hub {hub}, in {path} (valid {days} days):",
        highlight=False,
        soft_wrap=True,
    )
    out.print(f"  ca.pem, ca.key: {_WHERE['ca']}", highlight=False, soft_wrap=True)
    for role in role_names(path):
        where = _WHERE.get(role, f"the computer running autonomy {role!r} (it may put only command/{role})")
        out.print(f"  {role}.pem, {role}.key, {role}.json5: {where}", highlight=False, soft_wrap=True)
    out.print("each process: --bus-keys DIR --bus-role ROLE (keys stay chmod 600)", highlight=False, soft_wrap=True)
