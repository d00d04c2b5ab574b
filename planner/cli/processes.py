"""``rapt-plan frontseat | bridge | autonomy | log``: each piece of the loop as its own process.

On the water the front-seat is the vehicle; in rehearsal these commands run the same
pieces ``rapt-plan run`` wires together in one process, each until SIGINT or SIGTERM.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Annotated

import typer

from planner.cli.console import err, fail
from planner.cli.inputs import (
    ScenarioOpt,
    SurrogateOpt,
    Vehicle,
    ZenohConfig,
    ZenohConnect,
    ZenohListen,
    bus_session,
    load_surrogate,
    mission_and_scenario,
)
from planner.processes import arm_when_heard, run_until_signal, serve_until_signal, wait_for_signal

__all__ = ["frontseat", "bridge", "autonomy", "log"]


def frontseat(
    mission_file: Annotated[
        Path,
        typer.Argument(
            metavar="MISSION_OR_PLAN", help="Mission file (TOML), or a plan.json (then --scenario is an id)."
        ),
    ],
    mavlink: Annotated[str, typer.Option(help="pymavlink connection to serve on, e.g. udpin:127.0.0.1:14550.")],
    scenario: ScenarioOpt = None,
    speedup: Annotated[float | None, typer.Option(help="Real time times this factor (default: lock-step).")] = None,
    bare: Annotated[
        bool,
        typer.Option("--bare", help="Behave like a bare ArduSub: its streams, EKF start-up, no sonar, no referee."),
    ] = False,
    ekf_ready: Annotated[
        float, typer.Option("--ekf-ready", help="With --bare: vehicle seconds until the position estimate is ready.")
    ] = 5.0,
) -> None:
    """Serve the simulated front-seat of one scenario on a MAVLink connection."""
    from planner.flight import flight_from_plan, is_plan
    from sim.uuv.frontseat import FrontSeat

    if is_plan(mission_file):
        try:
            flight = flight_from_plan(mission_file, scenario)
        except ValueError as exc:
            fail(str(exc))
        mission, u, sid = flight.mission, flight.u, flight.scenario_id
    else:
        mission, u, sid = mission_and_scenario(mission_file, scenario)
    try:
        fs = FrontSeat(
            mission,
            u,
            mavlink,
            lockstep=speedup is None and not bare,
            speedup=speedup or 1.0,
            bare=bare,
            ekf_ready_s=ekf_ready,
        )
    except (ValueError, OSError) as exc:
        fail(f"--mavlink: {exc}")
    err.print(f"front-seat: mission {mission.name!r} scenario {sid} on {mavlink}", highlight=False, soft_wrap=True)
    serve_until_signal(fs)


def bridge(
    mavlink: Annotated[str, typer.Option(help="The vehicle's MAVLink connection (pymavlink string).")],
    vehicle: Vehicle = "uuv1",
    zenoh_listen: ZenohListen = ["tcp/127.0.0.1:7447"],
    zenoh_connect: ZenohConnect = [],
    zenoh_config: ZenohConfig = None,
    allow_commands: Annotated[bool, typer.Option("--allow-commands", help="Forward back-seat set-points.")] = False,
    signing_key: Annotated[Path | None, typer.Option(help="MAVLink 2 signing key file (32 bytes).")] = None,
    geofence: Annotated[str | None, typer.Option(help="north_min,north_max,east_min,east_max in m.")] = None,
    max_rate: Annotated[float | None, typer.Option("--max-rate", help="Set-points per second at most.")] = None,
    arm: Annotated[
        bool, typer.Option("--arm", help="Once the vehicle is heard: GUIDED and arm (needs --allow-commands).")
    ] = False,
) -> None:
    """Join a vehicle's MAVLink port (simulated or real) to the Zenoh bus."""
    from bridge.mavlink_bridge import MavlinkBridge
    from bridge.session import zenoh_config as make_config

    fence = None
    if geofence is not None:
        try:
            fence = [float(v) for v in geofence.split(",")]
        except ValueError:
            fail(f"--geofence: expected four numbers north_min,north_max,east_min,east_max, got {geofence!r}")
    try:
        conf = (
            make_config(config_file=zenoh_config)
            if zenoh_config is not None
            else make_config(listen=zenoh_listen, connect=zenoh_connect)
        )
        if arm and not allow_commands:
            fail("--arm: arming sends commands to the vehicle; add --allow-commands")
        with MavlinkBridge(
            mavlink,
            conf,
            vehicle=vehicle,
            allow_commands=allow_commands,
            geofence=fence,
            max_rate_hz=max_rate,
            signing_key=signing_key,
        ) as link:
            if arm and not arm_when_heard(link, timeout_s=30.0):
                fail("--mavlink: no vehicle HEARTBEAT within 30 s; check the connection string")
            wait_for_signal()
    except (ValueError, OSError) as exc:
        fail(str(exc))


def autonomy(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    scenario: ScenarioOpt = None,
    vehicle: Vehicle = "uuv1",
    source: Annotated[str, typer.Option(help="Name this autonomy publishes its set-points under.")] = "autonomy",
    zenoh_connect: ZenohConnect = ["tcp/127.0.0.1:7447"],
    zenoh_config: ZenohConfig = None,
    surrogate: SurrogateOpt = None,
    pacing: Annotated[
        str,
        typer.Option(
            help="lockstep (our simulated front-seat closes each step) or vehicle (decide every mission step of "
            "the vehicle's clock, from the start_ms put on meta/clock)."
        ),
    ] = "lockstep",
) -> None:
    """Run the back-seat autonomy of one scenario on the bus (or a trained surrogate of it).

    As source ``autonomy`` it also serves the scenario's map (``rapt/<v>/map/scenario``) that
    ``rapt-plan log`` records for Foxglove, whichever of the two starts first.
    """
    from bridge.keys import DEFAULT_ACTIVE
    from planner.backseat import PACINGS, BackSeat
    from planner.scenario_map import ScenarioMap

    if pacing not in PACINGS:
        fail(f"--pacing: expected one of {', '.join(PACINGS)}, got {pacing!r}")
    mission, u, sid = mission_and_scenario(mission_file, scenario)
    learned = load_surrogate(surrogate, mission)
    err.print(f"autonomy: mission {mission.name!r} scenario {sid}", highlight=False, soft_wrap=True)
    session = bus_session(zenoh_connect, zenoh_config)

    def start() -> contextlib.ExitStack:
        """The back-seat, and (as the flying source) the scenario's map for a logger on the bus."""
        with contextlib.ExitStack() as parts:
            if source == DEFAULT_ACTIVE:
                parts.enter_context(ScenarioMap(session, vehicle, mission, u))
            parts.enter_context(BackSeat(session, vehicle, mission, u, source=source, surrogate=learned, pacing=pacing))
            return parts.pop_all()

    run_until_signal(session, start)


def log(
    out_file: Annotated[Path, typer.Option("--out", help="MCAP file to write.")],
    vehicle: Vehicle = "uuv1",
    zenoh_connect: ZenohConnect = ["tcp/127.0.0.1:7447"],
    zenoh_config: ZenohConfig = None,
) -> None:
    """Record a vehicle's bus traffic to MCAP until stopped."""
    from bridge.logger import McapLogger

    session = bus_session(zenoh_connect, zenoh_config)
    run_until_signal(session, lambda: McapLogger(out_file, session, vehicle=vehicle))
