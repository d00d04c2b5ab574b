"""``rapt-plan frontseat | bridge | autonomy | log``: each piece of the loop as its own process.

On the water the front-seat is the vehicle; in rehearsal these commands run the same
pieces ``rapt-plan run`` wires together in one process, each until SIGINT or SIGTERM.

With ``--bus-keys DIR`` the bridge, the autonomy and the logger join the range's secure bus
(mutual TLS, access by role; ``docs/range-network.md``), each as its role: ``bridge`` (the hub),
the autonomy's source name, ``logger``. The front-seat is the vehicle: it speaks only MAVLink
(signed with ``--signing-key`` on the bridge's side) and never joins the bus, so it takes no keys.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Annotated

import typer

from planner.cli.console import err, fail
from planner.cli.inputs import (
    BusKeys,
    BusRole,
    FoxgloveOpt,
    ScenarioOpt,
    SurrogateOpt,
    Vehicle,
    ZenohConfig,
    ZenohConnect,
    ZenohListen,
    bus_config,
    bus_session,
    live_address,
    load_surrogate,
    mission_and_scenario,
    say_live,
)
from planner.fly.lifecycle import arm_when_heard, run_until_signal, serve_until_signal, wait_for, wait_for_signal
from rapt.errors import RaptError

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
    jitter: Annotated[
        float,
        typer.Option(
            "--jitter",
            help="With --bare: send each position and attitude report up to this many vehicle seconds early or "
            "late (uniform, seeded; stamped with its true time), as over a radio link.",
        ),
    ] = 0.0,
    drop_reports: Annotated[
        float,
        typer.Option("--drop-reports", help="With --bare: this share of position and attitude reports is never sent."),
    ] = 0.0,
    seed: Annotated[int, typer.Option(help="Seed of --jitter and --drop-reports.")] = 0,
    inject_bias: Annotated[
        str | None,
        typer.Option(
            "--inject-bias",
            help="Fly a biased vehicle for rehearsal, e.g. speed=1.15,current_offset=0.3 (see rapt-plan run).",
        ),
    ] = None,
) -> None:
    """Serve the simulated front-seat of one scenario on a MAVLink connection."""
    from planner.fly.flight import flight_from_plan, is_plan
    from sim.uuv.ardusub.frontseat import FrontSeat
    from sim.uuv.ardusub.jitter import check_report_timing
    from sim.uuv.bias import parse_bias

    for name, given in (("--jitter", jitter), ("--drop-reports", drop_reports)):
        if given and not bare:
            fail(f"{name}: only with --bare (the lock-step front-seat closes each step itself); add --bare")
    try:
        check_report_timing(jitter, drop_reports)
    except ValueError as exc:  # "jitter: ..." or "drop_reports: ...": name the option
        field, why = str(exc).split(": ", 1)
        fail(f"--{field.replace('_', '-')}: {why}")
    try:
        bias = parse_bias(inject_bias) if inject_bias is not None else None
    except ValueError as exc:
        fail(f"--inject-bias: {exc}")

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
            report_jitter_s=jitter,
            drop_reports=drop_reports,
            seed=seed,
            bias=bias,
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
    bus_keys: BusKeys = None,
    bus_role: BusRole = None,
    allow_commands: Annotated[bool, typer.Option("--allow-commands", help="Forward back-seat set-points.")] = False,
    signing_key: Annotated[
        Path | None,
        typer.Option(
            help="MAVLink 2 signing with this key file (32 bytes or 64 hex digits), given to the disarmed vehicle "
            "once heard (needs --allow-commands); refused on a link where the vehicle takes unsigned commands "
            "(its channel 0).",
        ),
    ] = None,
    geofence: Annotated[str | None, typer.Option(help="north_min,north_max,east_min,east_max in m.")] = None,
    max_rate: Annotated[float | None, typer.Option("--max-rate", help="Set-points per second at most.")] = None,
    arm: Annotated[
        bool, typer.Option("--arm", help="Once the vehicle is heard: GUIDED and arm (needs --allow-commands).")
    ] = False,
    foxglove: FoxgloveOpt = None,
) -> None:
    """Join a vehicle's MAVLink port (simulated or real) to the Zenoh bus.

    With --bus-keys DIR it is the secure bus's hub: role bridge (the default --bus-role). Set-points
    from a source that is not the active one are counted and logged; what the hub's access rules
    refuse is printed by Zenoh itself with
    RUST_LOG=zenoh::net::routing::interceptor::access_control=trace (every allowed message too).
    """
    import zenoh

    from bridge.mavlink_bridge import MavlinkBridge

    zenoh.try_init_log_from_env()  # only with RUST_LOG set: Zenoh's own log, the access rules' refusals in it

    fence = None
    if geofence is not None:
        try:
            fence = [float(v) for v in geofence.split(",")]
        except ValueError:
            fail(f"--geofence: expected four numbers north_min,north_max,east_min,east_max, got {geofence!r}")
    if bus_keys is not None and (bus_role or "bridge") != "bridge":
        fail(f"--bus-role: the bridge is the hub of the secure bus, role 'bridge', not {bus_role!r}; drop --bus-role")
    conf = bus_config(
        zenoh_listen,
        zenoh_connect,
        zenoh_config,
        bus_keys,
        "bridge" if bus_keys is not None else bus_role,
        endpoints_given=zenoh_listen != ["tcp/127.0.0.1:7447"] or bool(zenoh_connect),
    )
    live = live_address(foxglove)
    if arm and not allow_commands:
        fail("--arm: arming sends commands to the vehicle; add --allow-commands")
    if signing_key is not None and not allow_commands:
        fail(
            "--signing-key: the bridge gives the vehicle the key (SETUP_SIGNING) and checks its link with a command; "
            "add --allow-commands"
        )
    view_link = None
    if live is not None and bus_keys is None:
        from bridge.view_link import ViewLink

        view_link = ViewLink(vehicle)  # the view's own link, its telemetry thinned to a screen's rate
        view_link.add_to(conf)
    try:
        session = zenoh.open(conf)
    except zenoh.ZError as exc:
        if view_link is not None:
            view_link.close()
        fail(f"--zenoh-listen: the bus cannot start: {exc}")
    try:
        with contextlib.ExitStack() as parts:
            if live is not None:  # up before the vehicle is heard: it shows the bring-up too
                from bridge.live_process import LiveViewProcess

                # a process of its own, joined to this hub: the bridge forwards set-points and shares nothing with it
                access = (
                    {"keys_dir": bus_keys, "role": "logger"} if view_link is None else {"connect": [view_link.endpoint]}
                )
                view = parts.enter_context(LiveViewProcess(vehicle=vehicle, host=live[0], port=live[1], **access))
                say_live((live[0], view.port))
            link = parts.enter_context(
                MavlinkBridge(
                    mavlink,
                    session,
                    vehicle=vehicle,
                    allow_commands=allow_commands,
                    geofence=fence,
                    max_rate_hz=max_rate,
                    signing_key=signing_key,
                    accept_unsigned=signing_key is not None,  # until the vehicle holds the key
                )
            )
            if (signing_key is not None or arm) and not wait_for(lambda: link.target is not None, 30.0, poll_s=0.05):
                fail("--mavlink: no vehicle HEARTBEAT within 30 s; check the connection string")
            if signing_key is not None:  # before anything else is asked of the vehicle
                from planner.fly.vehicle.signing import sign_vehicle

                err.print(f"bridge: {sign_vehicle(link, mavlink)}", highlight=False, soft_wrap=True)
            if arm:
                arm_when_heard(link)  # heard already; RefusedError if GUIDED or arming never takes
            wait_for_signal()
    except (RaptError, ValueError, OSError) as exc:
        fail(str(exc))
    finally:
        session.close()
        if view_link is not None:
            view_link.close()


def autonomy(
    mission_file: Annotated[Path, typer.Argument(help="Mission file (TOML).")],
    scenario: ScenarioOpt = None,
    vehicle: Vehicle = "uuv1",
    source: Annotated[str, typer.Option(help="Name this autonomy publishes its set-points under.")] = "autonomy",
    zenoh_connect: ZenohConnect = ["tcp/127.0.0.1:7447"],
    zenoh_config: ZenohConfig = None,
    bus_keys: BusKeys = None,
    bus_role: BusRole = None,
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
    ``rapt-plan log`` records for Foxglove, whichever of the two starts first. With --bus-keys DIR
    its role is its source name (the default --bus-role): the hub lets it put ``command/<source>`` only.
    """
    from bridge.keys import DEFAULT_ACTIVE
    from planner.fly.backseat import PACINGS, BackSeat
    from planner.fly.scenario_map import ScenarioMap

    if pacing not in PACINGS:
        fail(f"--pacing: expected one of {', '.join(PACINGS)}, got {pacing!r}")
    if bus_keys is not None and bus_role is not None and bus_role != source:
        fail(
            f"--bus-role: autonomy {source!r} puts command/{source}, which only role {source!r} may; "
            f"drop --bus-role or give --source {bus_role}"
        )
    mission, u, sid = mission_and_scenario(mission_file, scenario)
    learned = load_surrogate(surrogate, mission)
    err.print(f"autonomy: mission {mission.name!r} scenario {sid}", highlight=False, soft_wrap=True)
    session = bus_session(
        zenoh_connect,
        zenoh_config,
        bus_keys,
        source if bus_keys is not None else bus_role,
        endpoints_given=zenoh_connect != ["tcp/127.0.0.1:7447"],
    )

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
    bus_keys: BusKeys = None,
    bus_role: BusRole = None,
    foxglove: FoxgloveOpt = None,
) -> None:
    """Record a vehicle's bus traffic to MCAP until stopped.

    With --bus-keys DIR it joins as role logger (the default --bus-role) and records which role
    each channel came from, by the hub's rules (DIR's bridge.json5 if there, else the roles in DIR).
    """
    from bridge.logger import McapLogger
    from planner.fly.run_bus import put_roles_of

    live = live_address(foxglove)
    role = (bus_role or "logger") if bus_keys is not None else bus_role
    session = bus_session(
        zenoh_connect, zenoh_config, bus_keys, role, endpoints_given=zenoh_connect != ["tcp/127.0.0.1:7447"]
    )
    roles = None if bus_keys is None else put_roles_of(bus_keys, vehicle)

    def start() -> contextlib.ExitStack:
        """The live view first (its subscriptions are up when the logger's arrival puts the map), the logger."""
        with contextlib.ExitStack() as parts:
            if live is not None:
                from bridge.live_view import LiveView

                parts.enter_context(LiveView(session, vehicle=vehicle, host=live[0], port=live[1]))
                say_live(live)
            parts.enter_context(McapLogger(out_file, session, vehicle=vehicle, roles=roles))
            return parts.pop_all()

    try:
        run_until_signal(session, start)
    except RaptError as exc:
        fail(str(exc))
