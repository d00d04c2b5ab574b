"""Software-in-the-loop figures (issue 5), measured in one run on loopback.

1. Lock-step SIL of the 2017 range mission with MCAP logging on: simulated seconds per
   wall second (target >= 100x), and whether the scores equal the batch simulator's.
2. Bridge round trip: a vehicle's telemetry step in over MAVLink -> bridge -> Zenoh ->
   back-seat autonomy -> Zenoh -> bridge -> set-point out over MAVLink; p50 and p99
   (target p99 <= 2 ms).
3. Sustained load, as a new user tries it: ``rapt-plan bridge --mavlink udpin:...`` and
   ``rapt-plan log`` as processes of their own, ATTITUDE frames from a pymavlink sender in a
   third, at 20,000 and 5,000 frames/s side by side: sent, received by the bridge, logged, and
   each loss counter as the log's ``rapt.losses`` reports it (sequence gaps at the bridge, its
   socket's kernel drops, bus gaps, write errors; target: zero lost at 20,000/s for 60 s).
   ``--load-in-process`` runs the bridge and the logger in this process instead, on one
   session, as ``rapt-plan run --log`` does (they then share one interpreter lock).
4. The Foxglove live view's cost, side by side with none: part 3's load at 20,000 frames/s with
   ``rapt-plan log --foxglove`` and a client subscribed to every channel against ``rapt-plan
   log`` alone (frames lost, the logger's CPU seconds per 1,000 frames and their ratio; target
   nothing lost and <= 1.10), and part 2's round trip with a live view joined to the back-seat's
   bus as ``rapt-plan run --foxglove`` starts it (a process of its own, over the hub's view link,
   bridge.view_link) and a subscribed client
   against none, and with clients connecting and leaving over and over,
   alternated (p50 and p99 and their ratios).

Run:  python benchmarks/sil.py [--scenarios 5] [--trips 2000] [--rates 20000,5000] [--seconds 60] [--quick]
      python benchmarks/sil.py --only live [--seconds 60] [--trips 2000] [--repeats 2]   (part 4 alone)
      python benchmarks/sil.py --only load --quick   (part 3 alone)

``--quick`` prints the same three results from a short run: 2 scenarios, 300 round trips,
5 seconds of sustained load (the targets are judged the same way, on less data).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

import sim.uuv  # noqa: E402
from bridge.logger import LOSSES_METADATA, RAW_TOPIC, McapLogger, read_log, read_metadata  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.session import open_session, zenoh_config  # noqa: E402
from planner.fly.backseat import BackSeat  # noqa: E402
from planner.fly.run_bus import free_port  # noqa: E402
from planner.fly.sil.loop import run_sil  # noqa: E402

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


def first_valid_scenario(mission) -> np.ndarray:
    """A scenario of ``mission`` the simulator flies (the first valid one of a seeded draw)."""
    X = np.random.default_rng(0).random((40, mission.dim))
    return X[np.flatnonzero(sim.uuv.simulate(mission, X).valid)[0]]


def round_trip_ms(mission, u, trips: int, bus: tuple[zenoh.Session, zenoh.Session] | None = None) -> np.ndarray:
    """Milliseconds from the last frame of each telemetry step leaving the vehicle to its set-point arriving.

    ``bus`` is the bridge's session and the back-seat's, left open (two processes' worth of bus
    between them); by default both run on one session of their own. The first 50 steps warm up.
    """
    port = free_port()
    vehicle = mavutil.mavlink_connection(
        f"udpin:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega"
    )
    own = bus is None
    if bus is None:
        session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
        bus = (session, session)
    lat = []
    try:
        with (
            BackSeat(bus[1], "uuv1", mission, u),
            MavlinkBridge(f"udpout:127.0.0.1:{port}", bus[0], vehicle="uuv1", allow_commands=True) as bridge,
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
    finally:
        if own:
            bus[0].close()
        vehicle.close()
    return np.array(lat)


def round_trip(mission, trips: int) -> None:
    """Part 2: the round trip with the bridge and the back-seat on one session."""
    lat = round_trip_ms(mission, first_valid_scenario(mission), trips)
    print(
        f"\n2. Bridge round trip (MAVLink -> Zenoh -> autonomy -> Zenoh -> MAVLink), {lat.size} steps: "
        f"p50 {np.percentile(lat, 50):.2f} ms, p99 {np.percentile(lat, 99):.2f} ms, max {lat.max():.2f} ms "
        f"(target p99 <= 2 ms)"
    )


# The sender runs in a process of its own: the bridge and the logger get the GIL to themselves.
# An optional fourth argument is the first sequence number (a later burst goes on where the last ended).
_SENDER = """
import os, sys, time
os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil
port, rate, seconds = int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3])
c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=1, source_component=1, dialect="ardupilotmega")
c.mav.seq = int(sys.argv[4]) if len(sys.argv) > 4 else 0
sent, start = 0, time.perf_counter()
while (now := time.perf_counter() - start) < seconds:
    while sent < int(now * rate):
        c.mav.attitude_send(sent & 0xFFFFFFFF, 0.1, 0.2, 0.3, 0.0, 0.0, 0.0)
        sent += 1
    time.sleep(0.0005)
print(sent, time.perf_counter() - start)
"""


def _cli(*args: str) -> subprocess.Popen:
    cmd = [sys.executable, "-m", "planner.cli", *args]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


class _BridgeStatus:
    """The latest ``status/bridge`` of a bridge, heard on the bus from a session of our own (opened from ``config``)."""

    def __init__(self, config: zenoh.Config):
        self.latest: dict = {}
        self.session = zenoh.open(config)
        self.sub = self.session.declare_subscriber("rapt/uuv1/status/bridge", self._on)

    def _on(self, sample) -> None:  # a Zenoh callback: only store
        self.latest = json.loads(sample.payload.to_bytes())

    def drained(self, sent: int, quiet_s: float = 3.0, timeout_s: float = 120.0) -> None:
        """Wait until the bridge has read all ``sent`` frames (or its counters stop moving for ``quiet_s``)."""
        deadline, last, since = time.monotonic() + timeout_s, None, time.monotonic()
        while time.monotonic() < deadline:
            b = self.latest
            seen = b.get("frames_in", 0) + max(0, b.get("kernel_dropped", 0))
            if seen >= sent:
                return
            if seen != last:
                last, since = seen, time.monotonic()
            elif time.monotonic() - since > quiet_s:
                return
            time.sleep(0.1)

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


@dataclass
class BusOptions:
    """How the processes of a load run join the bus: the options of ``rapt-plan bridge`` (the hub) and of
    ``rapt-plan log``, the hub's TCP port, and the config of the session this harness listens on."""

    bridge: list[str]
    logger: list[str]
    hub_port: int
    listener: Callable[[], zenoh.Config]

    @classmethod
    def tcp(cls) -> BusOptions:
        """Plain Zenoh TCP on a free loopback port, as a new user runs it."""
        port = free_port(socket.SOCK_STREAM)
        endpoint = f"tcp/127.0.0.1:{port}"
        return cls(
            ["--zenoh-listen", endpoint], ["--zenoh-connect", endpoint], port, lambda: zenoh_config(connect=endpoint)
        )


def _wait_listening(port: int, proc: subprocess.Popen, timeout_s: float = 60.0) -> None:
    """Wait until ``proc`` accepts TCP connections on loopback ``port``; its stderr if it ends first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"the hub ended before listening: {proc.communicate()[1].strip()[-500:]}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"nothing listens on 127.0.0.1:{port} after {timeout_s:g} s")


def process_cpu_s(pid: int) -> float:
    """A process's CPU time so far (user + system), in seconds."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class LoadRig:
    """``rapt-plan bridge`` and ``rapt-plan log`` as processes of their own, fed ATTITUDE frames in bursts by a
    pymavlink sender in a third.

    A context manager: entering starts both and waits until the logger hears the bridge;
    :meth:`burst` sends one burst and waits until the bridge has read it; leaving stops the
    logger, then the bridge (as an operator ends a run) and reads the log into :attr:`messages`
    and its ``rapt.losses`` into :attr:`losses`.
    """

    def __init__(self, path: Path, bus: BusOptions | None = None, logger_args: tuple[str, ...] = ()):
        self.path = path
        self.bus = bus if bus is not None else BusOptions.tcp()
        self.logger_args = logger_args
        self.port = free_port()
        self.sent = 0
        self.messages: list = []
        self.losses: dict = {}
        self._procs: list[subprocess.Popen] = []
        self._status: _BridgeStatus | None = None

    def start(self) -> None:
        """Start the bridge and the logger, without waiting for them (:meth:`ready` waits)."""
        bridge = _cli("bridge", "--mavlink", f"udpin:127.0.0.1:{self.port}", *self.bus.bridge)
        self._procs = [_cli("log", "--out", str(self.path), *self.bus.logger, *self.logger_args), bridge]

    def ready(self, settle_s: float = 2.0) -> None:
        """Wait until the hub listens, the bridge's status is heard and the logger's file exists, then ``settle_s``
        (the logger's subscription reaches the bridge)."""
        _wait_listening(self.bus.hub_port, self._procs[1])
        self._status = _BridgeStatus(self.bus.listener())
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (self._status.latest and self.path.exists()):
            time.sleep(0.2)
        time.sleep(settle_s)

    def __enter__(self) -> LoadRig:
        try:
            self.start()
            self.ready()
        except BaseException:
            self.finish(settle_s=0.0, read=False)
            raise
        return self

    @property
    def pids(self) -> dict[str, int]:
        """The process ids of the bridge and the logger."""
        return {"bridge": self._procs[1].pid, "logger": self._procs[0].pid}

    def burst(self, rate: int, seconds: float) -> int:
        """Send ATTITUDE frames at ``rate`` per second for ``seconds``; return once the bridge has read them
        (or its counters stopped); the number sent."""
        assert self._status is not None, "burst inside the with block"
        sender = [sys.executable, "-c", _SENDER, str(self.port), str(rate), str(seconds), str(self.sent % 256)]
        sent = int(subprocess.run(sender, capture_output=True, text=True, check=True).stdout.split()[0])
        self.sent += sent
        self._status.drained(self.sent)
        return sent

    def finish(self, settle_s: float = 2.5, read: bool = True) -> None:
        """After ``settle_s`` (two more statuses: the last counts reach the logger), stop the logger, then the
        bridge (as an operator ends a run), and (unless not ``read``, after a failure) read the log."""
        time.sleep(settle_s)
        if self._status is not None:
            self._status.close()
            self._status = None
        for proc in self._procs:  # the logger first
            if proc.poll() is None:
                proc.send_signal(2)
            proc.communicate(timeout=120)
        if read:
            self.messages = read_log(self.path)
            self.losses = read_metadata(self.path).get(LOSSES_METADATA, {})

    def __exit__(self, *exc) -> None:
        ok = exc[0] is None
        self.finish(settle_s=2.5 if ok else 0.0, read=ok)


def sustained_processes(rate: int, seconds: float) -> dict:
    """One run with ``rapt-plan bridge`` and ``rapt-plan log`` as processes; the counters from the log."""
    with tempfile.TemporaryDirectory() as tmp:
        with LoadRig(Path(tmp) / "load.mcap") as rig:
            sent = rig.burst(rate, seconds)
        logged = sum(1 for topic, _, _ in rig.messages if topic == RAW_TOPIC)
        b = [p for topic, _, p in rig.messages if topic.endswith("/status/bridge")][-1]
    return _load_row(rate, sent, b, logged, rig.losses)


def sustained_one(rate: int, seconds: float) -> dict:
    """One run with the bridge and the logger in this process on one session (as ``rapt-plan run --log``)."""
    port = free_port()
    session = open_session(listen=[f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "load.mcap"
        with McapLogger(path, session, vehicle="uuv1") as logger:
            with MavlinkBridge(f"udpin:127.0.0.1:{port}", session, vehicle="uuv1") as bridge:
                out = subprocess.run(
                    [sys.executable, "-c", _SENDER, str(port), str(rate), str(seconds)],
                    capture_output=True,
                    text=True,
                    check=True,
                )
                sent = int(out.stdout.split()[0])
                deadline = time.monotonic() + 120
                while time.monotonic() < deadline:  # until the bridge has read (or lost) every frame
                    b = bridge.stats
                    if b["frames_in"] + max(0, b["kernel_dropped"]) >= sent:
                        break
                    time.sleep(0.05)
                time.sleep(0.5)
                b = bridge.stats
            while (
                logger.stats["received"] + logger.stats["bus_lost"] < 2 * b["frames_in"] and time.monotonic() < deadline
            ):
                time.sleep(0.05)
        logged = sum(1 for topic, _, _ in read_log(path) if topic == RAW_TOPIC)
        losses = read_metadata(path).get(LOSSES_METADATA, {})
    session.close()
    return _load_row(rate, sent, b, logged, losses)


def _load_row(rate: int, sent: int, bridge: dict, logged: int, losses: dict) -> dict:
    """One rate's row: what was sent, read by the bridge, logged, and lost by each counter."""
    return {
        "rate": rate,
        "sent": sent,
        "bridge_in": bridge["frames_in"],
        "logged": logged,
        "link_lost": bridge["link_lost"],
        "kernel_dropped": bridge["kernel_dropped"],
        "bus_lost": int(losses.get("bus_lost", -1)),
        "write_errors": int(losses.get("write_errors", -1)),
        "reported": int(losses.get("total", -1)),
        "rcvbuf": bridge["rcvbuf_bytes"],
    }


def sustained(rates: list[int], seconds: float, in_process: bool = False) -> None:
    rows = [(sustained_one if in_process else sustained_processes)(rate, seconds) for rate in rates]
    how = (
        "bridge and logger in one process, one session"
        if in_process
        else "rapt-plan bridge + rapt-plan log (Zenoh TCP)"
    )
    print(f"\n3. Sustained load for {seconds:g} s: pymavlink sender -> UDP -> {how}")
    head = "frames/s sent bridge_in logged logged_% seq_gaps kernel bus write_err reported".split()
    print(" ".join(f"{h.replace('_', ' '):>10}" for h in head))
    for r in rows:
        cells = (r["rate"], r["sent"], r["bridge_in"], r["logged"])
        counters = ("link_lost", "kernel_dropped", "bus_lost", "write_errors", "reported")
        print(
            " ".join(f"{v:>10,}" for v in cells)
            + f" {r['logged'] / max(r['sent'], 1):>10.3%}"
            + "".join(f" {r[k]:>10,}" for k in counters)
        )
    unaccounted = ", ".join(f"{r['sent'] - r['logged'] - r['reported']:,}" for r in rows)
    print(f"   unaccounted (sent - logged - reported): {unaccounted}; UDP receive buffer {rows[0]['rcvbuf']:,} bytes")
    print(f"   (target: 20,000/s logged 100 %, every loss reported; load average {os.getloadavg()[0]:.1f} at the end)")


def _load_cpu(rate: int, seconds: float, live: bool) -> dict:
    """Part 3's load through ``rapt-plan bridge`` and ``rapt-plan log`` (with ``--foxglove`` and a client when
    ``live``): frames lost, and the logger's and the bridge's CPU seconds over the burst."""
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port(socket.SOCK_STREAM)
        args = ("--foxglove", f"127.0.0.1:{port}") if live else ()
        with LoadRig(Path(tmp) / "load.mcap", logger_args=args) as rig:
            client = _client(f"ws://127.0.0.1:{port}", "client") if live else None
            try:
                time.sleep(1.0 if live else 0.0)  # connected and subscribed
                pids = rig.pids
                before = {k: process_cpu_s(p) for k, p in pids.items()}
                sent = rig.burst(rate, seconds)
                cpu = {k: process_cpu_s(p) - before[k] for k, p in pids.items()}
            finally:
                shown = _messages_of(client) if client is not None else 0
        logged = sum(1 for topic, _, _ in rig.messages if topic == RAW_TOPIC)
    return {"sent": sent, "logged": logged, "lost": sent - logged, "cpu": cpu, "shown": shown}


# A Foxglove client in a process of its own, as the crew's Foxglove is: subscribes to every channel and reads
# until SIGTERM, then prints how many messages it received; with "churn" it connects, subscribes to everything
# and leaves, over and over.
_CLIENT = """
import json, signal, sys, time
from websockets.sync.client import connect
url, churn = sys.argv[1], sys.argv[2] == "churn"
received = 0
def stop(*_):
    print(received, flush=True)
    sys.exit(0)
signal.signal(signal.SIGTERM, stop)
while True:
    try:
        with connect(url, subprotocols=["foxglove.sdk.v1"], open_timeout=5, max_size=None) as ws:
            subs = 0
            started = time.monotonic()
            while not churn or time.monotonic() - started < 0.05:
                try:
                    frame = ws.recv(timeout=0.05)
                except TimeoutError:
                    continue
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg.get("op") == "advertise":
                        ids = [{"id": (subs := subs + 1), "channelId": ch["id"]} for ch in msg["channels"]]
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": ids}))
                else:
                    received += 1
    except OSError:
        time.sleep(0.05)
"""


def _client(url: str, how: str) -> subprocess.Popen:
    """The crew's Foxglove on ``url`` (``how``: "client" stays subscribed, "churn" comes and goes)."""
    return subprocess.Popen([sys.executable, "-c", _CLIENT, url, how], stdout=subprocess.PIPE, text=True)


def _messages_of(client: subprocess.Popen) -> int:
    """Stop ``client``; how many messages it received."""
    client.terminate()
    out, _ = client.communicate(timeout=10)
    return int(out.strip() or 0)


def _trip_with_live(mission, u, trips: int, how: str) -> np.ndarray:
    """Part 2's round trip with nothing else (``how`` "none"), with a live view joined to the back-seat's bus as
    ``rapt-plan run --foxglove`` starts it (a process of its own) with no client ("alone"), a client subscribed
    to every channel ("client"), or clients connecting, subscribing and leaving over and over ("churn")."""
    from bridge.live_process import LiveViewProcess
    from bridge.view_link import ViewLink

    endpoint = f"tcp/127.0.0.1:{free_port(socket.SOCK_STREAM)}"
    link = ViewLink("uuv1")
    session = open_session(listen=[endpoint], extend=link.add_to)
    try:
        if how == "none":
            return round_trip_ms(mission, u, trips, (session, session))
        with LiveViewProcess(vehicle="uuv1", port=0, connect=[link.endpoint]) as view:
            client = _client(view.url, how) if how != "alone" else None
            try:
                time.sleep(1.0)  # connected and subscribed
                return round_trip_ms(mission, u, trips, (session, session))
            finally:
                if client is not None:
                    _messages_of(client)
    finally:
        session.close()
        link.close()


def live_cost(mission, rate: int, seconds: float, trips: int, repeats: int = 2) -> None:
    """Part 4: what a live view with a client attached costs, side by side with none (module docstring)."""
    rows = {False: [], True: []}
    for _ in range(repeats):  # alternated: the machine's drift falls on both
        for live in (False, True):
            rows[live].append(_load_cpu(rate, seconds, live))
    print(f"\n4a. Live view under load: {rate:,} frames/s for {seconds:g} s, rapt-plan log with and without --foxglove")
    print(f"{'':>22} {'sent':>10} {'lost':>8} {'logger cpu s/1000':>18} {'bridge cpu s/1000':>18} {'shown':>8}")
    per = {}
    for live in (False, True):
        for r in rows[live]:
            lg, br = 1000 * r["cpu"]["logger"] / r["sent"], 1000 * r["cpu"]["bridge"] / r["sent"]
            per.setdefault(live, []).append(lg)
            name = "live view + client" if live else "no live view"
            print(f"{name:>22} {r['sent']:>10,} {r['lost']:>8,} {lg:>18.4f} {br:>18.4f} {r['shown']:>8,}")
    ratio = np.median(per[True]) / np.median(per[False])
    print(f"   logger CPU per frame, live / none (medians): {ratio:.3f} (target <= 1.10, nothing lost)")
    u = first_valid_scenario(mission)
    hows = {
        "none": "no live view",
        "alone": "live view, no client",
        "client": "live view + client",
        "churn": "clients come and go",
    }
    lat: dict[str, list] = {h: [] for h in hows}
    for _ in range(repeats):
        for how in hows:
            lat[how].append(_trip_with_live(mission, u, trips, how))
    runs = {h: np.concatenate(v) for h, v in lat.items()}
    p99s = {h: [float(np.percentile(x, 99)) for x in v] for h, v in lat.items()}  # one per run: their spread is noise
    print(
        f"\n4b. Round trip with a live view (its own process) on the back-seat's bus, {repeats} runs of {trips} "
        "steps each, alternated"
    )
    print(
        f"{'':>22} {'p50 ms':>8} {'p99 ms, median':>15} {'p99 runs, min-max':>18} {'p50 / none':>11} {'p99 / none':>11}"
    )
    base = runs["none"]
    for how, name in hows.items():
        r50 = np.percentile(runs[how], 50) / np.percentile(base, 50)
        r99 = np.median(p99s[how]) / np.median(p99s["none"])
        spread = f"{min(p99s[how]):.3f}-{max(p99s[how]):.3f}"
        print(
            f"{name:>22} {np.percentile(runs[how], 50):>8.3f} {np.median(p99s[how]):>15.3f} {spread:>18} "
            f"{r50:>11.3f} {r99:>11.3f}"
        )
    print(
        "   within noise when a case's p99 runs fall inside the spread of the runs without a live view "
        f"(their max / min: {max(p99s['none']) / min(p99s['none']):.3f})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", type=int, default=None, help="lock-step SIL runs (default 5; --quick: 2)")
    ap.add_argument("--trips", type=int, default=None, help="bridge round trips (default 2000; --quick: 300)")
    ap.add_argument("--rates", default="20000,5000", help="sustained-load rates, frames/s, comma-separated")
    ap.add_argument("--only", choices=("lockstep", "trip", "load", "live"), default=None, help="run one part")
    ap.add_argument("--load-in-process", action="store_true", help="part 3 with bridge and logger in this process")
    ap.add_argument("--seconds", type=float, default=None, help="sustained load (default 60; --quick: 5)")
    ap.add_argument("--repeats", type=int, default=2, help="part 4: runs of each case, alternated (default 2)")
    ap.add_argument("--quick", action="store_true", help="a short run of all three parts (well under a minute)")
    args = ap.parse_args()
    if args.scenarios is None:
        args.scenarios = 2 if args.quick else 5
    if args.trips is None:
        args.trips = 300 if args.quick else 2000
    if args.seconds is None:
        args.seconds = 5.0 if args.quick else 60.0
    mission = sim.uuv.load_mission(MISSION)
    if args.only in (None, "lockstep"):
        lockstep(mission, args.scenarios)
    if args.only in (None, "trip"):
        round_trip(mission, args.trips)
    if args.only in (None, "load"):
        sustained([int(r) for r in args.rates.split(",")], args.seconds, args.load_in_process)
    if args.only in (None, "live"):
        live_cost(mission, int(args.rates.split(",")[0]), args.seconds, args.trips, args.repeats)


if __name__ == "__main__":
    main()
