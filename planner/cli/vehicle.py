"""``rapt-plan run --mavlink``: a plan's scenario on a vehicle we do not simulate; bring-up shown as it happens."""

from __future__ import annotations

from pathlib import Path

from rich.table import Table

from planner.cli.console import err, fail, print_table

__all__ = ["run_on_vehicle"]


def run_on_vehicle(
    flight,
    source: Path,
    connection: str,
    *,
    log: Path | None,
    timeout: float | None,
    action: str,
    record_only: list[str] | None = None,
    heartbeat_timeout: float = 15.0,
    bus_keys: Path | None = None,
    live: tuple[str, int] | None = None,
    guard,
    start_tolerance_m: float,
    transit: bool,
    signing_key: Path | None,
    drift_transit_m: float,
) -> None:
    """Fly ``flight`` at ``connection``; print the bring-up timeline, the end, the mode and the decisions' figures."""
    from planner.fly.flight import is_plan
    from planner.fly.vehicle.bringup import BringUpTimeouts
    from planner.fly.vehicle.run import run_vehicle
    from rapt.errors import RaptError
    from sim.uuv.scoring import mode_name

    if timeout is not None and timeout <= 0:
        fail(f"--timeout: expected seconds > 0, got {timeout}")
    if heartbeat_timeout <= 0:
        fail(f"--heartbeat-timeout: expected seconds > 0, got {heartbeat_timeout}")
    timeouts = BringUpTimeouts(heartbeat=heartbeat_timeout)

    def say(step) -> None:
        if step.status == "failed":
            return  # the error line says it
        mark = {"ok": "[green]ok[/]", "failed": "[red]failed[/]"}.get(step.status, f"[yellow]{step.status}[/]")
        err.print(f"{step.wall_s:8.1f} s  {step.name:<9} {mark}  {step.detail}", highlight=False, soft_wrap=True)

    from planner.cli.inputs import say_live

    say_live(live)
    try:
        result = run_vehicle(
            flight,
            connection,
            log_path=log,
            action=action,
            record_only=record_only or [],
            timeout_s=timeout,
            timeouts=timeouts,
            say=say,
            bus_keys=bus_keys,
            live=live,
            guard=guard,
            start_tolerance_m=start_tolerance_m,
            transit=transit,
            signing_key=signing_key,
            drift_transit_m=drift_transit_m,
        )
    except KeyboardInterrupt:
        fail("stopped by the operator: the vehicle was told to surface and disarm")
    except (RaptError, ValueError, RuntimeError, TimeoutError, ConnectionError) as exc:
        fail(str(exc))
    predicted = _predicted_mode(source, flight.scenario_id) if is_plan(source) else None
    table = Table(title=f"{flight.mission.name} scenario {flight.scenario_id} on {connection}")
    table.add_column("", justify="left")
    table.add_column("value", justify="right")
    table.add_row("ended", result.ended)
    table.add_row("watchdog", result.watchdog or "did not intervene")
    for reason, detail in result.violations.items():
        table.add_row(f"recorded: {reason}", detail)
    table.add_row("observed mode", mode_name(result.scores))
    if predicted is not None:
        table.add_row("predicted mode", predicted)
    table.add_row("scenario time", f"{result.sim_s:,.0f} s in {result.wall_s:,.1f} s wall")
    d = result.decisions
    table.add_row("decisions (missed, stale)", f"{d.get('decisions', 0)} ({d.get('missed', 0)}, {d.get('stale', 0)})")
    if d.get("latency_ms_p50") is not None:
        table.add_row("decision latency p50 / p99", f"{d['latency_ms_p50']:.1f} / {d['latency_ms_p99']:.1f} ms")
    t = result.telemetry
    table.add_row("telemetry late / repeated", f"{t.get('out_of_order', 0)} / {t.get('duplicates', 0)}")
    if log is not None:
        table.add_row("log", str(log))
    print_table(table)


def _predicted_mode(source: Path, scenario_id: str) -> str | None:
    from planner.common.plans import load_plan

    try:
        return str(load_plan(source).scenario(scenario_id)["predicted"]["mode"])
    except (KeyError, ValueError):
        return None
