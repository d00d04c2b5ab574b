"""``rapt-plan run``: fly one scenario software-in-the-loop and print how it ended."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from planner.cli.console import fail, print_table
from planner.cli.inputs import (
    BusKeys,
    FoxgloveOpt,
    ScenarioOpt,
    SurrogateOpt,
    live_address,
    load_surrogate,
    mission_and_scenario,
    say_live,
)
from rapt.errors import RaptError

__all__ = ["run"]


def run(
    mission_file: Annotated[
        Path,
        typer.Argument(metavar="MISSION_OR_PLAN", help="Mission file (TOML), or a plan.json from rapt-plan generate."),
    ],
    scenario: ScenarioOpt = None,
    speedup: Annotated[float | None, typer.Option(help="Real time times this factor (default: lock-step).")] = None,
    log: Annotated[Path | None, typer.Option(help="Record the bus to this MCAP file.")] = None,
    timeout: Annotated[
        float | None,
        typer.Option(help="Give up after this many wall seconds (default: 600 in the loop; with --mavlink none)."),
    ] = None,
    inject_bias: Annotated[
        str | None,
        typer.Option(
            "--inject-bias",
            help="Fly a biased vehicle for rehearsal, e.g. speed=1.15,current_offset=0.3 "
            "(speed, current_scale, current_offset, current_cross, heading, battery, start_time; see sim.uuv.bias). "
            "Not written to the log.",
        ),
    ] = None,
    stochastic: Annotated[bool, typer.Option(help="Navigation drift and current perturbations on (seeded).")] = False,
    seed: Annotated[int, typer.Option(help="Seed of the stochastic effects.")] = 0,
    surrogate: SurrogateOpt = None,
    mavlink: Annotated[
        str | None,
        typer.Option(
            "--mavlink",
            help="Fly a vehicle we do not simulate at this pymavlink connection (tcp:HOST:PORT, udpin:..., "
            "a serial port): bring-up, vehicle-paced autonomy, virtual range elements, watchdog.",
        ),
    ] = None,
    watchdog_action: Annotated[
        str, typer.Option("--watchdog-action", help="With --mavlink: what the watchdog does when it takes over.")
    ] = "surface",
    watchdog_record: Annotated[
        list[str] | None,
        typer.Option(
            "--watchdog-record",
            help="With --mavlink: a watchdog reason to log without taking control (repeatable), e.g. nogo "
            "where the no-go areas are virtual; reasons: collision, nogo, operational_area, battery, "
            "stale_commands, link_lost.",
        ),
    ] = None,
    heartbeat_timeout: Annotated[
        float, typer.Option("--heartbeat-timeout", help="With --mavlink: seconds to wait for the vehicle's HEARTBEAT.")
    ] = 15.0,
    bus_keys: BusKeys = None,
    foxglove: FoxgloveOpt = None,
    no_guard: Annotated[
        bool,
        typer.Option(
            "--no-guard",
            help="With --mavlink: fly without the onboard guard (a Lua script that surfaces the vehicle when this "
            "computer's heartbeat stops in GUIDED); the timeline and the log say so.",
        ),
    ] = False,
    guard_timeout: Annotated[
        float,
        typer.Option(
            "--guard-timeout", help="With --mavlink: vehicle seconds of silence before the guard surfaces it."
        ),
    ] = 10.0,
    guard_path: Annotated[
        str,
        typer.Option(
            "--guard-path",
            help="With --mavlink: the guard script's path on the vehicle (APM/scripts/... on an SD card).",
        ),
    ] = "scripts/rapt_guard.lua",
    guard_reboot: Annotated[
        bool,
        typer.Option(
            "--guard-reboot",
            help="With --mavlink: if scripting is off, turn it on (SCR_ENABLE 1) and reboot the vehicle, only while "
            "it is disarmed.",
        ),
    ] = False,
    transit: Annotated[
        bool,
        typer.Option(
            "--transit",
            help="With --mavlink: a vehicle farther than --start-tolerance from the scenario's start is flown there "
            "at depth first (logged, not scored) instead of refused.",
        ),
    ] = False,
    signing_key: Annotated[
        Path | None,
        typer.Option(
            "--signing-key",
            help="With --mavlink: MAVLink 2 signing with this key file (32 bytes or 64 hex digits), given to the "
            "disarmed vehicle at bring-up; refused on a link where the vehicle takes unsigned commands (its channel 0).",
        ),
    ] = None,
    start_tolerance: Annotated[
        float,
        typer.Option("--start-tolerance", help="With --mavlink: metres from the scenario's start the vehicle may be."),
    ] = 10.0,
    drift_transit: Annotated[
        float,
        typer.Option(
            "--drift-transit",
            help="With --mavlink: a disarmed vehicle up to this many metres from the scenario's start (as a current "
            "carries it during bring-up) is flown there at depth first (logged, not scored); 0: refuse it instead.",
        ),
    ] = 50.0,
) -> None:
    """Fly one scenario software-in-the-loop: front-seat, bridge, autonomy (and logger).

    With --surrogate the learned policy commands the vehicle while the expert autonomy
    keeps running beside it; the expert's commands are on the bus and in the log.
    With --mavlink the scenario is flown on the vehicle at that address instead.
    With --bus-keys DIR the parts talk over the range's secure bus, each as its role
    (the bridge is the hub; a --surrogate needs an autonomy role named surrogate in DIR).
    """
    from planner.fly.sil.rehearse import check_against_batch, fly
    from sim.uuv.bias import parse_bias

    try:
        bias = parse_bias(inject_bias) if inject_bias is not None else None
    except ValueError as exc:
        fail(f"--inject-bias: {exc}")
    flight = _flight(mission_file, scenario)
    live = live_address(foxglove)
    if bus_keys is not None:
        _check_bus_keys(bus_keys, surrogate is not None)
    if mavlink is not None:
        if not start_tolerance > 0:
            fail(f"--start-tolerance: expected metres > 0, got {start_tolerance}")
        if not drift_transit >= 0:
            fail(f"--drift-transit: expected metres >= 0 (0: refuse a drifted vehicle), got {drift_transit}")
        _check_not_with_mavlink(speedup is not None, bias is not None, stochastic, surrogate is not None)
        from planner.cli.vehicle import run_on_vehicle

        run_on_vehicle(
            flight,
            mission_file,
            mavlink,
            log=log,
            timeout=timeout,
            action=watchdog_action,
            record_only=watchdog_record or [],
            heartbeat_timeout=heartbeat_timeout,
            bus_keys=bus_keys,
            live=live,
            guard=None if no_guard else _guard(guard_timeout, guard_path, guard_reboot),
            start_tolerance_m=start_tolerance,
            transit=transit,
            signing_key=signing_key,
            drift_transit_m=drift_transit,
        )
        return
    if speedup is not None and speedup <= 0:
        fail(f"--speedup: expected a factor > 0, got {speedup}")
    learned = load_surrogate(surrogate, flight.mission)
    say_live(live)
    try:
        result = fly(
            flight,
            log_path=log,
            speedup=speedup,
            timeout_s=600.0 if timeout is None else timeout,
            bias=bias,
            stochastic=stochastic,
            seed=seed,
            surrogate=learned,
            bus_keys=bus_keys,
            live=live,
        )
    except (RaptError, ValueError, RuntimeError, TimeoutError, ConnectionError) as exc:
        fail(str(exc))
    batch = check_against_batch(flight, result.scores, bias=bias, stochastic=stochastic, seed=seed, surrogate=learned)
    flown_by = surrogate.name if learned is not None and surrogate is not None else None
    print_table(_result_table(flight, result, batch, bias, flown_by, stochastic, log))


def _guard(timeout_s: float, path: str, reboot: bool):
    """The onboard guard's options (:class:`planner.fly.vehicle.guard.GuardOptions`); a one-line error."""
    from planner.fly.vehicle.guard import GuardOptions

    try:
        return GuardOptions(timeout_s, path, reboot)
    except RaptError as exc:
        fail(str(exc))


def _flight(mission_file: Path, scenario: str | None):
    """The flight of MISSION_OR_PLAN's scenario (:class:`planner.fly.flight.Flight`); a one-line error."""
    from planner.fly.flight import Flight, flight_from_plan, is_plan

    if is_plan(mission_file):
        try:
            return flight_from_plan(mission_file, scenario)
        except ValueError as exc:
            fail(str(exc))
    mission, u, sid = mission_and_scenario(mission_file, scenario)
    return Flight(mission, u, sid, str(mission_file))


def _check_not_with_mavlink(speedup: bool, bias: bool, stochastic: bool, surrogate: bool) -> None:
    """A one-line error for an option given with --mavlink that only the simulated vehicle has."""
    for name, given in (
        ("--speedup", speedup),
        ("--inject-bias", bias),
        ("--stochastic", stochastic),
        ("--surrogate", surrogate),
    ):
        if given:
            fail(f"{name}: not with --mavlink (the vehicle keeps its own pace and physics); drop one of them")


def _result_table(flight, result, batch, bias, flown_by: str | None, stochastic: bool, log: Path | None) -> Table:
    """How the software-in-the-loop run ended, set against the batch simulator's run of the scenario."""
    from sim.uuv.scoring import mode_name

    table = Table(title=f"{flight.mission.name} scenario {flight.scenario_id}: software in the loop")
    table.add_column("", justify="left")
    table.add_column("value", justify="right")
    table.add_row("ended", result.ended)
    if flown_by is not None:
        table.add_row("flown by", f"surrogate {flown_by} (expert commands recorded)")
    table.add_row("mode", mode_name(result.scores))
    if bias is not None:
        table.add_row("injected bias", str(bias))
    table.add_row("simulated time", f"{result.sim_s:,.0f} s in {result.wall_s:.1f} s ({result.speedup:,.0f}x)")
    for name in ("mission_areas", "transmission", "recovery", "nogo_areas", "mission.battery_left"):
        if name in batch.names:
            table.add_row(name, f"{result.scores[batch.names.index(name)]:g}")
    if stochastic:  # the log holds what the navigation believed, the batch scores ground truth
        table.add_row("batch simulator's mode (ground truth)", batch.mode)
    else:
        table.add_row(
            "same scores as the batch simulator" + (" (same bias)" if bias is not None else ""),
            "yes" if batch.same else "NO",
        )
    if log is not None:
        table.add_row("log", str(log))
    return table


def _check_bus_keys(keys_dir: Path, surrogate: bool) -> None:
    """A one-line error before anything starts when DIR cannot fly this run (each role's files are checked next)."""
    from bridge.keys import SURROGATE_SOURCE
    from bridge.range_keys import role_names

    if not keys_dir.is_dir():
        fail(
            f"--bus-keys: {str(keys_dir)!r} is not a directory; make the keys with rapt-plan bus-keys DIR --vehicle NAME"
        )
    if surrogate and SURROGATE_SOURCE not in role_names(keys_dir):
        fail(
            f"--surrogate: on the secure bus the surrogate flies as autonomy role {SURROGATE_SOURCE!r}, which "
            f"{keys_dir} lacks; make the keys with --autonomy autonomy --autonomy {SURROGATE_SOURCE}"
        )
