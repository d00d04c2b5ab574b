"""Plain TCP versus mutual TLS with access control on the Zenoh bus (issue 29), side by side in one run.

Two configurations of the bus, measured in turn within every repeat (which goes first alternates):

- ``plain``: the bridge's session listens on loopback TCP as the hub; the others connect to it;
- ``secure``: the range's keys from :func:`bridge.range_keys.make_range_keys`, made in a
  temporary directory, and each process on its role's configuration
  (:func:`bridge.range_keys.role_config`, ``--bus-keys DIR`` on the command line): the bridge
  the hub with the access-control rules, the autonomy and the logger its clients over mutual
  TLS (the logger then also records which role each channel came from).

1. Round trip: a vehicle's telemetry step over MAVLink -> bridge -> bus -> back-seat autonomy
   -> bus -> bridge -> set-point over MAVLink, timed at the vehicle (``benchmarks/sil.py``'s
   part 2, here with the bridge and the autonomy on two sessions joined by the bus); p50, p99.
2. Throughput: ``rapt-plan bridge`` and ``rapt-plan log`` as processes (``benchmarks/sil.py``'s
   part 3), fed ATTITUDE frames by a sender process faster than they keep up; the frames per
   second the logger wrote (first to last frame of a burst, by its clock), what was lost, and
   the CPU time of bridge plus logger per logged frame.

Target: the secure bus costs at most 20 % of throughput and adds at most 0.5 ms to p99
(medians over the repeats; a p99 of all steps pooled is printed beside it).

Run:  python benchmarks/secure_bus.py [--trip-repeats 10] [--trips 1000] [--repeats 5] [--rate 40000]
                                      [--seconds 10] [--quick]

``--quick`` (under a minute): 4 repeats of 200 round trips, 3 bursts of 2 s, judged the same way.
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zenoh
from sil import (  # benchmarks/sil.py, beside this script
    MISSION,
    BusOptions,
    LoadRig,
    first_valid_scenario,
    process_cpu_s,
    round_trip_ms,
)

import sim.uuv
from bridge.logger import RAW_TOPIC
from bridge.range_keys import make_range_keys, role_config
from bridge.session import zenoh_config
from planner.fly.run_bus import free_port

#: The targets: the secure bus keeps at least 80 % of plain TCP's throughput and adds at most 0.5 ms to p99.
MAX_THROUGHPUT_COST = 0.20
MAX_P99_ADDED_MS = 0.5


@dataclass
class Configuration:
    """One way of joining the bus: the sessions of the round trip and the options of the load run's processes."""

    name: str
    trip_configs: Callable[[], tuple[zenoh.Config, zenoh.Config]]  # the bridge's (the hub) and the autonomy's
    load: BusOptions
    trips: list[np.ndarray] = field(default_factory=list)  # latencies (ms) of each repeat
    bursts: list[dict] = field(default_factory=list)  # each burst's window, frames sent and CPU time
    losses: dict = field(default_factory=dict)  # the load run's rapt.losses, as its log reports them


def plain() -> Configuration:
    """Plain Zenoh TCP on free loopback ports."""
    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    return Configuration(
        "plain TCP", lambda: (zenoh_config(listen=endpoint), zenoh_config(connect=endpoint)), BusOptions.tcp()
    )


def secure(directory: Path) -> Configuration:
    """Mutual TLS with access control: one range's keys for the round trip and one for the load run (own hubs)."""
    trip_keys = make_range_keys(directory / "trip", "uuv1", hub=f"tls/127.0.0.1:{free_port(socket.SOCK_STREAM)}")
    port = free_port(socket.SOCK_STREAM)
    load_keys = make_range_keys(directory / "load", "uuv1", hub=f"tls/127.0.0.1:{port}")
    load = BusOptions(
        ["--bus-keys", str(load_keys)],  # the hub, role bridge
        ["--bus-keys", str(load_keys), "--bus-role", "logger"],
        port,
        lambda: role_config(load_keys, "logger"),  # the harness hears status/bridge as a logger
    )
    return Configuration(
        "mTLS + ACL", lambda: (role_config(trip_keys, "bridge"), role_config(trip_keys, "autonomy")), load
    )


def _in_turn(configs: list[Configuration], repeat: int) -> list[Configuration]:
    """The configurations in this repeat's order: reversed every other repeat, so neither always goes first."""
    return configs if repeat % 2 == 0 else configs[::-1]


def round_trips(configs: list[Configuration], repeats: int, trips: int) -> None:
    """Each configuration's round trips, ``repeats`` times in turn, on sessions opened once per configuration."""
    mission = sim.uuv.load_mission(MISSION)
    u = first_valid_scenario(mission)
    sessions = []
    try:
        for c in configs:
            hub, client = c.trip_configs()
            sessions.append(zenoh.open(hub))
            sessions.append(zenoh.open(client))
        bus = {c.name: (sessions[2 * i], sessions[2 * i + 1]) for i, c in enumerate(configs)}
        for r in range(repeats):
            for c in _in_turn(configs, r):
                c.trips.append(round_trip_ms(mission, u, trips, bus[c.name]))
    finally:
        for s in sessions[::-1]:
            s.close()


def throughput(configs: list[Configuration], repeats: int, rate: int, seconds: float, tmp: Path) -> None:
    """Each configuration's load rig up at once, fed one burst per repeat in turn; then each burst's figures."""
    rigs = {c.name: LoadRig(tmp / f"{c.name.split()[0]}.mcap", c.load) for c in configs}
    ok = False
    try:
        for rig in rigs.values():
            rig.start()
        for rig in rigs.values():
            rig.ready(settle_s=0.0)
        time.sleep(2.0)  # the loggers' subscriptions reach their bridges
        for r in range(repeats):
            for c in _in_turn(configs, r):
                rig = rigs[c.name]
                pids = rig.pids.values()
                cpu0, start = sum(process_cpu_s(p) for p in pids), time.time_ns()
                sent = rig.burst(rate, seconds)
                time.sleep(0.5)  # the logger writes the last frames the bridge read
                c.bursts.append({"start_ns": start, "sent": sent, "cpu_s": sum(process_cpu_s(p) for p in pids) - cpu0})
        time.sleep(2.5)  # two more statuses of each bridge: its last counts reach its logger
        ok = True
    finally:
        for rig in rigs.values():
            rig.finish(settle_s=0.0, read=ok)
    for c in configs:
        rig = rigs[c.name]
        stamps = np.array(sorted(t for topic, t, _ in rig.messages if topic == RAW_TOPIC))
        starts = [b["start_ns"] for b in c.bursts] + [np.iinfo(np.int64).max]
        for b, (lo, hi) in zip(c.bursts, zip(starts, starts[1:], strict=False), strict=False):
            t = stamps[(stamps >= lo) & (stamps < hi)]
            b["logged"] = t.size
            b["fps"] = (t.size - 1) / ((t[-1] - t[0]) / 1e9) if t.size > 1 else 0.0
            b["cpu_us"] = b["cpu_s"] / max(t.size, 1) * 1e6
        c.losses = rig.losses


def report(configs: list[Configuration], rate: int, seconds: float) -> None:
    base, sec = configs
    print(
        f"1. Round trip (MAVLink -> bridge -> bus -> autonomy -> bus -> bridge -> MAVLink), {base.trips[0].size} steps"
    )
    print(f"{'repeat':>6} " + " ".join(f"{c.name + ' p50':>16} {c.name + ' p99':>16}" for c in configs))
    for r in range(len(base.trips)):
        cells = [np.percentile(c.trips[r], q) for c in configs for q in (50, 99)]
        print(f"{r + 1:>6} " + " ".join(f"{v:>13.3f} ms" for v in cells))
    med = {c.name: [float(np.median([np.percentile(t, q) for t in c.trips])) for q in (50, 99)] for c in configs}
    print(f"{'median':>6} " + " ".join(f"{v:>13.3f} ms" for c in configs for v in med[c.name]))
    pooled = [np.percentile(np.concatenate(c.trips), q) for c in configs for q in (50, 99)]
    print(f"{'pooled':>6} " + " ".join(f"{v:>13.3f} ms" for v in pooled) + "   (all steps together)")
    added = med[sec.name][1] - med[base.name][1]

    print(f"\n2. Throughput: rapt-plan bridge + rapt-plan log, {rate:,} ATTITUDE frames/s offered for {seconds:g} s")
    print(f"{'repeat':>6} " + " ".join(f"{c.name + ' frames/s':>20} {'lost':>8} {'CPU us/frame':>12}" for c in configs))
    for r in range(len(base.bursts)):
        row = [(b["fps"], b["sent"] - b["logged"], b["cpu_us"]) for b in (c.bursts[r] for c in configs)]
        print(f"{r + 1:>6} " + " ".join(f"{f:>20,.0f} {lost:>8,} {cpu:>12.1f}" for f, lost, cpu in row))
    fps = {c.name: float(np.median([b["fps"] for b in c.bursts])) for c in configs}
    cpu = {c.name: float(np.median([b["cpu_us"] for b in c.bursts])) for c in configs}
    print(f"{'median':>6} " + " ".join(f"{fps[c.name]:>20,.0f} {'':>8} {cpu[c.name]:>12.1f}" for c in configs))
    for c in configs:
        parts = ", ".join(f"{k} {c.losses.get(k, '?')}" for k in ("link_seq_gaps", "kernel_dropped", "bus_lost"))
        sent = sum(b["sent"] for b in c.bursts)
        logged = sum(b["logged"] for b in c.bursts)
        print(
            f"   {c.name}: {sent:,} sent, {logged:,} logged; the log reports {c.losses.get('total', '?')} lost ({parts})"
        )
    if max(fps.values()) > 0.95 * rate:
        print(f"   note: {max(fps, key=fps.get)} kept up with the offered rate; raise --rate to measure its ceiling")
    cost = 1 - fps[sec.name] / fps[base.name]

    print(f"\n{sec.name} versus {base.name} (medians; load average {os.getloadavg()[0]:.1f} at the end):")
    print(
        f"   throughput {fps[sec.name]:,.0f} / {fps[base.name]:,.0f} frames/s = {1 - cost:.1%} "
        f"(cost {cost:.1%}, target <= {MAX_THROUGHPUT_COST:.0%}): {'PASS' if cost <= MAX_THROUGHPUT_COST else 'FAIL'}"
    )
    print(
        f"   CPU per logged frame {cpu[sec.name]:.1f} / {cpu[base.name]:.1f} us = {cpu[sec.name] / cpu[base.name]:.2f}x"
    )
    print(
        f"   round trip p50 {med[sec.name][0]:.3f} / {med[base.name][0]:.3f} ms; p99 {med[sec.name][1]:.3f} / "
        f"{med[base.name][1]:.3f} ms, added {added:+.3f} ms (target <= {MAX_P99_ADDED_MS} ms): "
        f"{'PASS' if added <= MAX_P99_ADDED_MS else 'FAIL'}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trip-repeats", type=int, default=None, help="round-trip repeats (default 10; --quick: 4)")
    ap.add_argument("--trips", type=int, default=None, help="round trips per repeat (default 1000; --quick: 200)")
    ap.add_argument("--repeats", type=int, default=None, help="bursts of each configuration (default 5; --quick: 3)")
    ap.add_argument("--rate", type=int, default=40000, help="ATTITUDE frames/s offered (above what is kept up with)")
    ap.add_argument("--seconds", type=float, default=None, help="each burst (default 10; --quick: 2)")
    ap.add_argument("--quick", action="store_true", help="a short run of both parts (under a minute)")
    args = ap.parse_args()
    trip_repeats = args.trip_repeats or (4 if args.quick else 10)
    trips = args.trips or (200 if args.quick else 1000)
    repeats = args.repeats or (3 if args.quick else 5)
    seconds = args.seconds or (2.0 if args.quick else 10.0)
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory() as tmp:
        configs = [plain(), secure(Path(tmp) / "keys")]
        round_trips(configs, trip_repeats, trips)
        throughput(configs, repeats, args.rate, seconds, Path(tmp))
    report(configs, args.rate, seconds)
    print(f"   ({trip_repeats} x {trips} round trips and {repeats} bursts each, {time.monotonic() - t0:.0f} s)")


if __name__ == "__main__":
    main()
