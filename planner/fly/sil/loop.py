"""Software-in-the-loop: one scenario flown through the interfaces used on the water.

The simulated front-seat (:class:`sim.uuv.ardusub.frontseat.FrontSeat`) speaks MAVLink on loopback;
the bridge puts it on a Zenoh bus; the back-seat autonomy (:class:`planner.fly.backseat.
BackSeat`) flies it from the bus; the MCAP logger records everything.  In lock-step the
simulated clock advances when the back-seat answers each step, so a 45-minute mission
flies in seconds.  The run is scored from its recorded telemetry, the way a range day's
logs are (:func:`sim.uuv.replay.score_track`).
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.mavlink_bridge import MavlinkBridge  # noqa: E402
from bridge.service import Service  # noqa: E402
from bridge.session import receive, undeclare  # noqa: E402
from planner.common.scenario_record import SCENARIO_META, scenario_json  # noqa: E402
from planner.fly.backseat import BackSeat  # noqa: E402
from planner.fly.lifecycle import wait_for  # noqa: E402
from planner.fly.live import start_live_view  # noqa: E402
from planner.fly.run_bus import PART_ROLES, RunBus, free_port  # noqa: E402
from planner.fly.scenario_map import ScenarioMap  # noqa: E402
from rapt.errors import LinkTimeoutError  # noqa: E402
from sim.uuv.ardusub.frontseat import FrontSeat  # noqa: E402
from sim.uuv.mission import Mission  # noqa: E402
from sim.uuv.replay import TrackBuilder, score_track  # noqa: E402

__all__ = ["SilResult", "run_sil"]


@dataclass
class SilResult:
    scores: np.ndarray
    track: np.ndarray
    ended: str
    sim_s: float
    wall_s: float
    steps: int
    wp_aborted: list[bool]
    return_reason: int
    bridge_stats: dict = field(default_factory=dict)
    log_path: Path | None = None

    @property
    def speedup(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("inf")


class _Recorder(Service):
    """Builds the track from the bus's ordered raw frames (independent of the back-seat); starts at once."""

    _what = "recorder"

    def __init__(self, session, vehicle: str):
        super().__init__()
        self.builder = TrackBuilder()
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.sub = session.declare_subscriber(keys.raw(vehicle))
        self.start()

    def _open(self) -> None:
        self._spawn("sil-recorder", self._run)

    def _run(self) -> None:
        for sample in receive(self.sub):
            for msg in self.parser.parse_buffer(sample.payload.to_bytes()) or []:
                self.builder.add(msg)

    def _shutdown(self) -> None:
        undeclare(self.sub)  # ends the reader's receive()
        self._join(self._threads, timeout=5)


def _frontseat(mission: Mission, u: np.ndarray, port: int, speedup, bias, stochastic: bool, seed: int) -> FrontSeat:
    """The simulated front-seat on UDP ``port``: lock-step when ``speedup`` is None, else real time times it."""
    return FrontSeat(
        mission,
        u,
        f"udpin:127.0.0.1:{port}",
        lockstep=speedup is None,
        speedup=speedup or 1.0,
        bias=bias,
        stochastic=stochastic,
        seed=seed,
    )


def _fly_to_the_end(
    bus: RunBus, bridge: MavlinkBridge, fs: FrontSeat, vehicle: str, surrogate: bool, timeout_s: float
) -> None:
    """Once the bridge hears the front-seat (and takes the surrogate as the active source): GUIDED, arm,
    and wait for the front-seat to end the run; then for its last telemetry to reach the recorder and logger."""
    if not wait_for(lambda: bridge.target is not None, 10):
        raise LinkTimeoutError("front-seat: no HEARTBEAT on the MAVLink link within 10 s")
    if surrogate:
        bus.put(PART_ROLES["control"], keys.active(vehicle), keys.SURROGATE_SOURCE, when_heard=True)
        if not wait_for(lambda: bridge.active == keys.SURROGATE_SOURCE, 10):
            raise LinkTimeoutError("bridge: did not take the surrogate as the active source within 10 s")
    bridge.set_mode("GUIDED")
    bridge.arm(True)
    if not wait_for(lambda: fs.ended, timeout_s, poll_s=0.005):
        raise LinkTimeoutError(f"timeout_s: the run did not end within {timeout_s} s of wall time")
    time.sleep(0.3)  # let the last step's telemetry reach the recorder and the logger


def run_sil(
    mission: Mission,
    u,
    *,
    vehicle: str = "uuv1",
    log_path: str | Path | None = None,
    speedup: float | None = None,
    timeout_s: float = 600.0,
    scenario_id: str = "",
    mission_file: str = "",
    plan_id: str = "",
    bias=None,
    stochastic: bool = False,
    seed: int = 0,
    surrogate=None,
    bus_keys: str | Path | None = None,
    legs: tuple = (),
    live: tuple[str, int] | None = None,
) -> SilResult:
    """Fly scenario ``u`` through front-seat, bridge, back-seat (and logger); return its scores.

    ``speedup=None`` runs lock-step (as fast as the back-seat answers); a number runs the
    front-seat in real time times that factor.  ``bias`` (:class:`sim.uuv.bias.Bias`) makes the
    simulated front-seat a biased vehicle; it is not recorded in the log, whose metadata
    names only the mission, plan and scenario — ``rapt-plan compare`` estimates the bias
    blind, as from a real vehicle.  ``stochastic`` turns on the front-seat's navigation
    drift and current perturbations (seeded by ``seed``): the vehicle then reports where
    its navigation thinks it is, as a real one does.

    ``surrogate`` (:class:`sim.uuv.imitation.surrogate.Surrogate`) flies the vehicle as back-seat
    source ``"surrogate"``, made active on the bus, while the expert still runs as source
    ``"autonomy"`` and its commands are published (and logged) but not obeyed — the testbed
    of Figure 6.3.  The scores are then the surrogate's.

    ``bus_keys``: the range's keys directory (``rapt-plan bus-keys``); each part then joins the
    secure bus as its role (:data:`planner.fly.run_bus.PART_ROLES`; a surrogate as the autonomy role
    ``surrogate``, and the operator makes it active), the bridge's session being the hub.

    ``legs`` (a calibration run's, :mod:`sim.uuv.legs`) fly in place of the mission's autonomy and
    go into the log's scenario record. ``live``: ``(host, port)`` of a Foxglove live view of the run
    (:class:`bridge.live_view.LiveView`).
    """
    u = np.asarray(u, dtype=float)
    if surrogate is not None:
        surrogate.check(mission)
    port = free_port()
    roles = [keys.DEFAULT_ACTIVE] + (["logger"] if log_path is not None or live is not None else [])
    roles += [keys.SURROGATE_SOURCE, "operator"] if surrogate is not None else []
    bus = RunBus(bus_keys, vehicle=vehicle, roles=tuple(roles))  # keys checked before the front-seat starts
    fs = _frontseat(mission, u, port, speedup, bias, stochastic, seed)
    fs_thread = threading.Thread(target=fs.serve, name="frontseat", daemon=True)
    logger = bridge = backseat = recorder = learned = scenario_map = view = None
    started = time.perf_counter()
    try:
        fs_thread.start()
        view = start_live_view(bus, vehicle, mission, u, live)
        autonomy = bus.session(PART_ROLES["backseat"])
        heard = [keys.DEFAULT_ACTIVE]
        if log_path is not None:
            from bridge.logger import McapLogger

            scenario_map = ScenarioMap(
                bus.session(PART_ROLES["scenario_map"]), vehicle, mission, u
            ).start()  # put when the logger appears
            logger = McapLogger(
                log_path, bus.session(PART_ROLES["logger"]), vehicle=vehicle, roles=bus.put_roles()
            ).start()
            heard.append("logger")
        recorder = _Recorder(bus.session(PART_ROLES["recorder"]), vehicle)  # declared before the back-seat's token
        backseat = flying = BackSeat(autonomy, vehicle, mission, u, legs=legs).start()
        if surrogate is not None:
            learned = flying = BackSeat(
                bus.session(keys.SURROGATE_SOURCE),
                vehicle,
                mission,
                u,
                source=keys.SURROGATE_SOURCE,
                surrogate=surrogate,
            ).start()
            heard.append(keys.SURROGATE_SOURCE)
        bus.wait_for_parts(*heard)  # every part's subscriptions are at the hub before the first frame
        meta = scenario_json(mission, u, mission_file=mission_file, scenario_id=scenario_id, plan_id=plan_id, legs=legs)
        # the logger may be a client of the hub: put once it is heard
        bus.put(PART_ROLES["scenario_meta"], keys.meta(vehicle, SCENARIO_META), meta, when_heard=logger is not None)
        bridge = MavlinkBridge(
            f"udpout:127.0.0.1:{port}", bus.session("bridge"), vehicle=vehicle, allow_commands=True
        ).start()
        _fly_to_the_end(bus, bridge, fs, vehicle, surrogate is not None, timeout_s)
        wall = time.perf_counter() - started
        status = flying.autonomy  # the scores are those of whoever flew
        wp_aborted = [bool(v) for v in status.wp_aborted[0]]
        reason = int(status.return_reason[0])
        track = recorder.builder.track()
        stats = dict(bridge.stats)
    finally:
        for part in (learned, backseat, bridge, recorder, scenario_map, logger, view):
            if part is not None:
                part.close()
        fs.stop()
        fs_thread.join(timeout=5)
        fs.close()
        bus.close()
    scores = score_track(mission, u, track, wp_aborted, reason)
    return SilResult(
        scores,
        track,
        fs.stats.ended,
        fs.t,
        wall,
        fs.stats.ticks,
        wp_aborted,
        reason,
        stats,
        Path(log_path) if log_path else None,
    )
