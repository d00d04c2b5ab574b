"""What the commands are given, loaded and checked: mission files, scenarios, surrogates, the bus.

Several commands take the same arguments (a mission file, ``--scenario``, ``--surrogate``,
the Zenoh endpoints); their option declarations and loaders live here once, so every
command reports a bad one with the same one-line error.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from planner.cli.console import fail

__all__ = [
    "SurrogateOpt",
    "ScenarioOpt",
    "ZenohListen",
    "ZenohConnect",
    "ZenohConfig",
    "Vehicle",
    "BusKeys",
    "BusRole",
    "FoxgloveOpt",
    "live_address",
    "say_live",
    "load_mission",
    "mission_and_scenario",
    "load_surrogate",
    "bus_session",
    "bus_config",
]


SurrogateOpt = Annotated[
    Path | None,
    typer.Option(
        "--surrogate",
        help="A trained surrogate (.npz from `rapt-plan surrogate`) flies instead of the expert "
        "autonomy; it must have been trained for this mission.",
    ),
]


ScenarioOpt = Annotated[
    str | None,
    typer.Option(
        "--scenario",
        help="Row number of the mission's Sobol design (default: its first valid row), or a JSON file with 'u' "
        "or 'parameters'; with a plan, a scenario id such as pair1a.",
    ),
]


ZenohListen = Annotated[list[str], typer.Option("--zenoh-listen", help="Zenoh endpoints to listen on.")]


ZenohConnect = Annotated[list[str], typer.Option("--zenoh-connect", help="Zenoh endpoints to connect to.")]


ZenohConfig = Annotated[Path | None, typer.Option("--zenoh-config", help="Zenoh config file (real deployments).")]


Vehicle = Annotated[str, typer.Option("--vehicle", help="Vehicle name on the bus.")]


BusKeys = Annotated[
    Path | None,
    typer.Option(
        "--bus-keys",
        metavar="DIR",
        help="The range's keys (rapt-plan bus-keys): join the secure bus (mutual TLS, access by role) "
        "with the role's config instead of the loopback endpoints.",
    ),
]


FoxgloveOpt = Annotated[
    str | None,
    typer.Option(
        "--foxglove",
        metavar="[HOST:]PORT",
        help="Show the run live in Foxglove: a WebSocket server (foxglove.sdk.v1) on PORT, on loopback unless "
        "HOST is given (e.g. 8765, or 0.0.0.0:8765 for the range's network). The protocol has no "
        "authentication: anyone who reaches the port sees the run.",
    ),
]


def live_address(text: str | None) -> tuple[str, int] | None:
    """``--foxglove [HOST:]PORT`` as (host, port), None when not given; a one-line error when malformed."""
    if text is None:
        return None
    from bridge.live_view import parse_address
    from rapt.errors import InputError

    try:
        return parse_address(text)
    except InputError as exc:
        fail(str(exc))


def say_live(address: tuple[str, int] | None) -> None:
    """Tell the crew where the live view is (on stderr)."""
    if address is not None:
        from planner.cli.console import err

        host, port = address
        err.print(
            f"live view: ws://{host}:{port} (Foxglove: Open connection, Foxglove WebSocket)",
            highlight=False,
            soft_wrap=True,
        )


BusRole = Annotated[
    str | None,
    typer.Option("--bus-role", metavar="ROLE", help="With --bus-keys: the role to join as (default: see above)."),
]


def load_mission(mission_file: Path):
    """The mission file, loaded and validated, or a one-line error naming it."""
    import sim.uuv

    if not mission_file.is_file():
        fail(f"MISSION_FILE: {mission_file} does not exist; give the path of a mission TOML file")
    try:
        return sim.uuv.load_mission(mission_file)
    except ValueError as exc:
        fail(str(exc))


def mission_and_scenario(mission_file: Path, scenario: str | None):
    """(mission, unit-cube row, scenario id) of ``--scenario`` (default: the design's first valid row),
    or a one-line error naming why the scenario is invalid and the first valid rows."""
    import sim.uuv
    from planner.common.scenarios import SEARCHED_ROWS, resolve_scenario, valid_design_rows

    mission = load_mission(mission_file)
    if scenario is None:
        valid = valid_design_rows(mission, 1)
        if not valid:
            fail(
                f"--scenario: none of the first {SEARCHED_ROWS} rows of mission {mission.name!r}'s design is "
                "valid; give a scenario as a JSON file, or widen the mission's parameter ranges"
            )
        scenario = str(valid[0])
    try:
        u, sid = resolve_scenario(mission, scenario)
        scen = sim.uuv.scenario.make_scenarios(mission, u[None, :])
    except ValueError as exc:
        fail(str(exc))
    if not scen.valid[0]:
        valid = valid_design_rows(mission)
        fail(
            f"--scenario: scenario {scenario} is invalid for mission {mission.name!r} ({scen.invalid_reason[0]}); "
            + (f"valid ones include {', '.join(map(str, valid))}" if valid else "give a valid one as a JSON file")
        )
    return mission, u, sid


def load_surrogate(path: Path | None, mission):
    """The surrogate file for ``mission``, or a one-line error naming --surrogate."""
    if path is None:
        return None
    from sim.uuv.imitation.surrogate import Surrogate

    try:
        return Surrogate.load(path, mission)
    except (ValueError, OSError) as exc:
        fail(f"--surrogate: {exc}")


def _role_config(keys_dir: Path | None, role: str | None, config_file: Path | None, endpoints_given: bool):
    """The role's checked Zenoh config with --bus-keys (None without), or a one-line error."""
    if keys_dir is None:
        if role is not None:
            fail("--bus-role: only with --bus-keys DIR (the role's certificate and config are in DIR)")
        return None
    if config_file is not None:
        fail("--zenoh-config: give either --bus-keys DIR or --zenoh-config FILE, not both")
    if endpoints_given:
        fail("--zenoh-listen/--zenoh-connect: with --bus-keys the role's config in DIR names the hub; drop them")
    if role is None:
        fail("--bus-role: name the role to join as (one of the roles in DIR)")
    from bridge.range_keys import role_config

    try:
        return role_config(keys_dir, role)
    except (ValueError, OSError) as exc:
        fail(str(exc))


def bus_config(
    listen: list[str],
    connect: list[str],
    config_file: Path | None,
    keys_dir: Path | None,
    role: str | None,
    *,
    endpoints_given: bool = False,
):
    """The hub's Zenoh config: the role's from --bus-keys, the config file as given, else the loopback endpoints."""
    from bridge.session import zenoh_config

    config = _role_config(keys_dir, role, config_file, endpoints_given)
    if config is not None:
        return config
    try:
        if config_file is not None:
            return zenoh_config(config_file=config_file)
        return zenoh_config(listen=listen, connect=connect)
    except (ValueError, OSError) as exc:
        fail(str(exc))


def bus_session(
    connect: list[str],
    config_file: Path | None,
    keys_dir: Path | None = None,
    role: str | None = None,
    *,
    endpoints_given: bool = False,
):
    """A Zenoh session joining the bus: as ``role`` with --bus-keys, the config file as given, else the
    endpoints (loopback by default)."""
    import zenoh

    from bridge.session import open_session

    config = _role_config(keys_dir, role, config_file, endpoints_given)
    try:
        if config is not None:
            try:
                return zenoh.open(config)
            except zenoh.ZError as exc:
                fail(
                    f"--bus-keys: role {role!r} could not join the hub named in {keys_dir}/{role}.json5 "
                    f"({str(exc).split(' at ')[0]}); start rapt-plan bridge --bus-keys first, or check the network"
                )
        return open_session(config_file=config_file) if config_file is not None else open_session(connect=connect)
    except (ValueError, OSError) as exc:
        fail(str(exc))
