"""Software-in-the-loop figures (issue 5), measured in one run on loopback.

1. Lock-step SIL of the 2017 range mission with MCAP logging on: simulated seconds per
   wall second (target >= 100x), and whether the scores equal the batch simulator's.
2. Bridge round trip: a vehicle's telemetry step in over MAVLink -> bridge -> Zenoh ->
   back-seat autonomy -> Zenoh -> bridge -> set-point out over MAVLink; p50 and p99
   (target p99 <= 2 ms).
3. Sustained load: MAVLink frames at 5,000/s through the bridge into the MCAP logger;
   frames sent, frames logged, loss (target: zero at 5,000/s for 60 s).

Run:  python benchmarks/sil.py [--scenarios 5] [--trips 2000] [--rate 5000] [--seconds 60] [--quick]

``--quick`` prints the same three results from a short run: 2 scenarios, 300 round trips,
5 seconds of sustained load (the targets are judged the same way, on less data).
"""

from __future__ import annotations

import argparse
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import sim.uuv  # noqa: E402
from bridge.logger import McapLogger, read_log  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.session import open_session  # noqa: E402
from planner.backseat import BackSeat  # noqa: E402
from planner.sil import free_port, run_sil  # noqa: E402

MISSION = Path(__file__).resolve().parents[1] / "examples" / "range2017.toml"


def lockstep(mission, n: int) -> None:
    X = np.random.default_rng(0).random((4 * n, mission.dim))
    batch = sim.uuv.simulate(mission, X)
    rows = np.flatnonzero(batch.valid)[:n]
    print(f"1. Lock-step SIL of {mission.name} with MCAP logging ({n} scenarios)")
    print(f"{'scenario':>8} {'ended':>12} {'simulated s':>11} {'wall s':>7} {'x real time':>11} {'= batch':>7}")
    speeds = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in rows:
            r = run_sil(mission, X[i], log_path=Path(tmp) / f"run{i}.mcap")
            same = np.array_equal(r.scores, batch.scores[i])
            speeds.append(r.speedup)
            print(f"{i:>8} {r.ended:>12} {r.sim_s:>11,.0f} {r.wall_s:>7.2f} {r.speedup:>11,.0f} {str(same):>7}")
    print(f"   median {np.median(speeds):,.0f}x real time (target >= 100x)")


def round_trip(mission, trips: int) -> None:
    """Time from the last frame of a telemetry step leaving the vehicle to its set-point arriving."""
    X = np.random.default_rng(0).random((40, mission.dim))
    u = X[np.flatnonzero(sim.uuv.simulate(mission, X).valid)[0]]
    port = free_port()
    vehicle = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega"
    )
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
    lat = []
    with (
        BackSeat(session, "uuv1", mission, u),
        MavlinkBridge(f"udpout:127.0.0.1:{port}", session, vehicle="uuv1", allow_commands=True) as bridge,
    ):
        m = vehicle.mav
        vehicle.recv_match(type="HEARTBEAT", blocking=True, timeout=5)  # the bridge has spoken: we can send
        deadline = time.monotonic() + 5
        while bridge.target is None and time.monotonic() < deadline:
            m.heartbeat_send(12, 3, 0, 4, 4)
            time.sleep(0.05)
        x, y = -480.0, -500.0
        for k in range(trips + 50):
            ms = k * 2000
            m.attitude_send(ms, 0, 0, 0.5, 0, 0, 0)
            m.local_position_ned_send(ms, y, x, 2.0, 0, 0, 0)
            m.battery_status_send(0, 0, 0, 2000, [15000] + [65535] * 9, -1, 0, k, 90)
            t0 = time.perf_counter()
            m.system_time_send(int(time.time() * 1e6), ms)
            reply = vehicle.recv_match(type="SET_POSITION_TARGET_LOCAL_NED", blocking=True, timeout=1)
            t1 = time.perf_counter()
            if reply is not None and reply.time_boot_ms == ms and k >= 50:  # 50 warm-up steps
                lat.append((t1 - t0) * 1e3)
            y += 1.0
        if k % 500 == 0:
            m.heartbeat_send(12, 3, 0, 4, 4)
    session.close()
    vehicle.close()
    lat = np.array(lat)
    print(
        f"\n2. Bridge round trip (MAVLink -> Zenoh -> autonomy -> Zenoh -> MAVLink), {lat.size} steps: "
        f"p50 {np.percentile(lat, 50):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms, max {lat.max():.2f} ms "
        f"(target p99 <= 2 ms)"
    )


def sustained(rate: int, seconds: float) -> None:
    port = free_port()
    vehicle = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega"
    )
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "load.mcap"
        with (
            McapLogger(path, session, vehicle="uuv1"),
            MavlinkBridge(f"udpout:127.0.0.1:{port}", session, vehicle="uuv1") as bridge,
        ):
            vehicle.recv_match(type="HEARTBEAT", blocking=True, timeout=5)
            sent = 0
            start = time.perf_counter()
            while (now := time.perf_counter() - start) < seconds:
                due = int(now * rate)
                while sent < due:
                    vehicle.mav.named_value_int_send(sent & 0xFFFFFFFF, b"seq", sent)
                    sent += 1
                time.sleep(0.0005)
            time.sleep(1.0)  # drain
            bridge_in = bridge.stats["frames_in"]
        logged = sum(1 for topic, _, _ in read_log(path) if topic.endswith("/raw") or topic == "/mavlink/raw")
    session.close()
    vehicle.close()
    print(
        f"\n3. Sustained load, {rate:,} frames/s for {seconds:g} s: sent {sent:,}, bridge received {bridge_in:,}, "
        f"logged {logged:,}, lost {sent - logged:,} ({(sent - logged) / max(sent, 1):.3%})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=None, help="lock-step SIL runs (default 5; --quick: 2)")
    ap.add_argument("--trips", type=int, default=None, help="bridge round trips (default 2000; --quick: 300)")
    ap.add_argument("--rate", type=int, default=5000)
    ap.add_argument("--seconds", type=float, default=None, help="sustained load (default 60; --quick: 5)")
    ap.add_argument("--quick", action="store_true", help="a short run of all three parts (well under a minute)")
    args = ap.parse_args()
    if args.scenarios is None:
        args.scenarios = 2 if args.quick else 5
    if args.trips is None:
        args.trips = 300 if args.quick else 2000
    if args.seconds is None:
        args.seconds = 5.0 if args.quick else 60.0
    mission = sim.uuv.load_mission(MISSION)
    lockstep(mission, args.scenarios)
    round_trip(mission, args.trips)
    sustained(args.rate, args.seconds)


if __name__ == "__main__":
    main()
