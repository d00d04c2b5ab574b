"""Read a run back from the MCAP log our logger wrote — SIL or a real vehicle through the bridge.

What a run's log holds (:mod:`bridge.logger`): the vehicle's MAVLink frames in order on
``/mavlink/raw``, the back-seat's set-points (``rapt/<v>/command/<source>``), its status
(aborted waypoints, why it turned home), and the scenario metadata (``meta/scenario``:
mission, plan id, scenario id, unit-cube row).  :func:`read_run` turns that into a
:class:`LoggedRun`: one row per reported step (:data:`STEP_FIELDS`), the set-point the
vehicle was given at each step, and an account of anything lost: damaged or missing parts of
the file (:attr:`LoggedRun.problems`) and the frames lost on the way to it, as the logger
counted them (:attr:`LoggedRun.losses`, from the ``rapt.losses`` metadata record).

A log is read record by record and never modified.  A logger killed mid-run leaves a
file with no summary or footer and a half-written last chunk: everything before it is
read, a chunk that fails its CRC or decompression is skipped (and counted), and
:attr:`LoggedRun.problems` says what is missing — down to "the run's end is not in the
log", in which case the run has no observed mode.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
from mcap.exceptions import McapError  # noqa: E402
from mcap.records import Channel, Chunk, Footer, Message, Metadata, Schema  # noqa: E402
from mcap.stream_reader import StreamReader, breakup_chunk  # noqa: E402
from pymavlink.dialects.v20 import ardupilotmega as mavlink  # noqa: E402

from bridge import keys  # noqa: E402
from bridge.frames import message_id  # noqa: E402
from bridge.logger import LOSSES_METADATA, RAW_TOPIC  # noqa: E402
from planner.common.scenario_record import SCENARIO_META, metadata_fields, paced_clock  # noqa: E402
from planner.common.telemetry import VIRTUAL_BATTERY_ID, TrackSampler, VehicleTelemetry  # noqa: E402
from planner.review.run_checks import RunEvidence, run_checks  # noqa: E402
from rapt.errors import FileFormatError  # noqa: E402
from sim.uuv.geo import LocalFrame  # noqa: E402
from sim.uuv.interface import decode_command  # noqa: E402
from sim.uuv.replay import TrackBuilder  # noqa: E402

__all__ = ["LoggedRun", "read_run", "STEP_FIELDS", "LogError"]

#: Columns of :attr:`LoggedRun.steps`; the first six are :data:`sim.uuv.replay.TRACK_FIELDS`.
STEP_FIELDS = ("t", "x", "y", "heading", "energy_hj", "surfaced", "surge", "yaw_rate")


class LogError(FileFormatError):
    """A log that cannot be compared at all (missing, not MCAP, no scenario metadata).

    A :class:`rapt.errors.FileFormatError`, so also an ``InputError``, a ``RaptError`` and a ``ValueError``.
    """


@dataclass
class LoggedRun:
    path: Path
    meta: dict
    steps: np.ndarray  # (n, STEP_FIELDS)
    setpoints: np.ndarray  # (n, 3): heading, speed, surface of the set-point applied after each step; NaN: none
    ended: str  # the front-seat's "run ended: <reason>", "" if not in the log
    wp_aborted: list[bool]
    return_reason: int
    complete_file: bool
    problems: list[str] = field(default_factory=list)
    messages: int = 0
    events: list[dict] = field(default_factory=list)  # bring-up steps, watchdog interventions, the referee's end
    # (n,) vehicle seconds from each step to the set-point flown after it reaching the bus: 0 on a
    # lock-step front-seat (it waits for it), inf where no set-point answered this very step, NaN: none
    setpoint_delay_s: np.ndarray | None = None
    # what the logger counted as lost on the way (:meth:`bridge.logger.McapLogger.losses`: total,
    # link_lost, bus_lost, write_errors, ...); None for a log without the record (older, or killed)
    losses: dict | None = None
    # the automatic checks of the run itself (planner.review.run_checks), as dicts
    checks: list[dict] = field(default_factory=list)

    @property
    def frames_lost(self) -> int | str:
        """Frames lost on the way to this log (``losses["total"]``), "unknown" without the record."""
        total = (self.losses or {}).get("total")
        return total if isinstance(total, int) else "unknown"

    @property
    def track(self) -> np.ndarray:
        """(n, TRACK_FIELDS) rows for :func:`sim.uuv.replay.score_track`."""
        return self.steps[:, :6]

    @property
    def scenario_id(self) -> str:
        return str(self.meta.get("scenario_id", ""))

    @property
    def has_end(self) -> bool:
        return bool(self.ended)


def _losses(record: dict[str, str]) -> dict:
    """A ``rapt.losses`` record's values as numbers and dicts ("unknown" stays as it is)."""
    out: dict = {}
    for key, text in record.items():
        try:
            out[key] = json.loads(text)
        except ValueError:
            out[key] = text
    return out


class _Steps(TrackBuilder):
    """The track's steps (closed as :class:`sim.uuv.replay.TrackBuilder` closes them) with the
    vehicle's surge and yaw rate added, and the front-seat's "run ended" report."""

    def __init__(self):
        super().__init__()
        self.ended = ""

    def add(self, msg) -> None:
        if msg.get_type() == "STATUSTEXT":
            text = msg.text if isinstance(msg.text, str) else bytes(msg.text).decode(errors="replace")
            if text.startswith("run ended:"):
                self.ended = text.split(":", 1)[1].strip().rstrip("\x00")
            return
        super().add(msg)

    def _row(self, ms: int, lp, att, bat) -> tuple[float, ...]:
        surge = float(np.hypot(np.float32(lp.vx), np.float32(lp.vy)))
        return super()._row(ms, lp, att, bat) + (surge, float(att.yawspeed))


class _PacedSteps:
    """The track of a vehicle-paced run: the referee's sampling (:class:`planner.common.telemetry.TrackSampler`) of the log."""

    def __init__(self, frame: LocalFrame, dt: float):
        self.telemetry = VehicleTelemetry(frame, VIRTUAL_BATTERY_ID)
        self.period_ms = int(round(dt * 1000))
        self.sampler: TrackSampler | None = None
        self.ended = ""
        self.row_log_ns: list[int] = []  # log time of the report that opened each row

    def begin(self, start_ms: int) -> None:
        self.sampler = TrackSampler(self.telemetry, start_ms, self.period_ms)

    @property
    def rows(self) -> list:
        return self.sampler.rows if self.sampler is not None else []

    def add(self, msg, log_ns: int = 0) -> None:
        if self.telemetry.add(msg) == "position" and self.sampler is not None and self.telemetry.pose is not None:
            if not self.ended and self.sampler.add(self.telemetry.pose) is not None:
                self.row_log_ns.append(int(log_ns))


#: MAVLink message ids a run's track needs.
TRACK_IDS = {
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    mavlink.MAVLINK_MSG_ID_ATTITUDE,
    mavlink.MAVLINK_MSG_ID_BATTERY_STATUS,
    mavlink.MAVLINK_MSG_ID_SYSTEM_TIME,
    mavlink.MAVLINK_MSG_ID_STATUSTEXT,
}
#: ... and its checks (planner.review.run_checks); everything else on /mavlink/raw is skipped unparsed.
WANTED_IDS = TRACK_IDS | {
    mavlink.MAVLINK_MSG_ID_HEARTBEAT,
    mavlink.MAVLINK_MSG_ID_EKF_STATUS_REPORT,
    mavlink.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS,
    mavlink.MAVLINK_MSG_ID_COMMAND_ACK,
    mavlink.MAVLINK_MSG_ID_PARAM_VALUE,
}


def _decode_frame(parser, frame: bytes):
    """One logged frame (the logger stores one per message) decoded if it is wanted; CRC-checked."""
    if message_id(frame) not in WANTED_IDS:  # not a frame's start, or not wanted
        return None
    try:
        return parser.decode(bytearray(frame))
    except Exception:  # a damaged frame: drop it, as a MAVLink parser would
        return None


def read_run(path: str | Path) -> LoggedRun:
    """Read one run's log (see the module docstring); LogError when nothing comparable is in it."""
    return RunLogReader(path).read()


class RunLogReader:
    """One pass over a run's log, record by record: a method per record and message kind.

    :meth:`read` streams the file (skipping damaged chunks), then turns what was gathered
    into a :class:`LoggedRun` with an account of what was lost.  Use :func:`read_run`.
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.channels: dict[int, Channel] = {}
        self.steps = _Steps()
        self.paced: _PacedSteps | None = None  # a vehicle-paced run (meta pacing "vehicle")
        self.start_ms = 0
        self.parser = mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self.meta: dict = {}
        self.commands: dict[str, dict[int, tuple[float, float, float, float]]] = {}
        self.command_log_ns: dict[str, dict[int, int]] = {}  # first log time of each tick's set-point
        self.log_ns = 0  # log time of the message being read
        self.status: dict = {}
        self.active = keys.DEFAULT_ACTIVE
        self.problems: list[str] = []
        self.events: list[dict] = []  # bring-up steps, watchdog interventions, the referee's end
        self.lost_chunks: list[tuple[int, int]] = []
        self.footer = False
        self.n_messages = 0
        self.losses: dict | None = None
        self.evidence = RunEvidence()  # what the run checks need

    def read(self) -> LoggedRun:
        """The run in the log; LogError when the file is missing, not MCAP, or has no scenario metadata."""
        path = self.path
        if not path.is_file():
            raise LogError(f"LOG: {path} does not exist")
        self._stream(path.stat().st_size)
        if not self.footer:
            self.problems.insert(0, "no summary or footer: the logger did not finish the file (killed mid-run?)")
        if self.lost_chunks:
            t0 = min(a for a, _ in self.lost_chunks) / 1e9
            t1 = max(b for _, b in self.lost_chunks) / 1e9
            self.problems.append(f"{len(self.lost_chunks)} damaged chunk(s) skipped (log time {t0:.3f}..{t1:.3f} s)")
        if not self.meta:
            raise LogError(
                f"LOG: {path} has no scenario metadata (meta/scenario); it was not written by "
                "rapt-plan run or a logger beside a planned run"
            )
        steps = self.paced if self.paced is not None else self.steps
        rows = np.array(steps.rows, dtype=float).reshape(-1, len(STEP_FIELDS))
        if rows.shape[0] == 0:
            self.problems.append("no complete telemetry step in the log")
        source, setpoints = self._setpoints(rows)
        delay = self._setpoint_delay(rows, source, setpoints)
        status = self.status
        st = status.get(source or keys.DEFAULT_ACTIVE) or (next(iter(status.values())) if status else {})
        if not steps.ended:
            last = rows[-1, 0] if rows.shape[0] else 0.0
            self.problems.append(f"the run's end is not in the log (track stops at {last:,.0f} s): no observed mode")
        return LoggedRun(
            path,
            self.meta,
            rows,
            setpoints,
            steps.ended,
            [bool(v) for v in st.get("wp_aborted", [])],
            int(st.get("return_reason", 0)),
            self.footer,
            self.problems,
            self.n_messages,
            self.events,
            delay,
            self.losses,
            [c.as_dict() for c in self._checks()],
        )

    def _checks(self):
        """The run's automatic checks (planner.review.run_checks), told which parts of the file were lost."""
        self.evidence.lost_log_ns = list(self.lost_chunks)
        return run_checks(self.evidence, self.losses)

    # -- the file ----------------------------------------------------------------------
    def _stream(self, size: int) -> None:
        """Every readable record, in file order; a damaged chunk is skipped, a damaged tail ends the read."""
        path, consumed = self.path, 0
        with open(path, "rb") as f:
            reader = StreamReader(f, emit_chunks=True, record_size_limit=max(size, 1))
            try:
                for rec in reader.records:
                    consumed = f.tell()
                    if isinstance(rec, Chunk):
                        self.on_chunk(rec)
                    elif isinstance(rec, Footer):
                        self.footer = True
                    elif not isinstance(rec, Schema):
                        self.on_record(rec)
            except (McapError, EOFError, ValueError, OSError, MemoryError, IndexError, KeyError) as exc:
                if consumed == 0 and not self.channels:
                    raise LogError(
                        f"LOG: {path} is not an MCAP file our logger wrote ({type(exc).__name__}: "
                        f"{exc}); give the .mcap file of a run"
                    ) from None
                self.problems.append(
                    f"the file ends or is damaged after byte {consumed:,} of {size:,}; "
                    f"{size - consumed:,} bytes unreadable"
                )
            except Exception as exc:  # anything else from a damaged record: stop there, keep what was read
                self.problems.append(f"unreadable record after byte {consumed:,} of {size:,} ({type(exc).__name__})")

    def on_chunk(self, rec: Chunk) -> None:
        try:
            inner = breakup_chunk(rec, validate_crc=True)
        except Exception:  # CRC mismatch, bad compression: skip this chunk, keep going
            self.lost_chunks.append((rec.message_start_time, rec.message_end_time))
            return
        for r in inner:
            self.on_record(r)

    def on_record(self, rec) -> None:
        if isinstance(rec, Channel):
            self.channels[rec.id] = rec
        elif isinstance(rec, Message):
            self.on_message(rec)
        elif isinstance(rec, Metadata) and rec.name == SCENARIO_META:
            self.on_metadata(rec)
        elif isinstance(rec, Metadata) and rec.name == LOSSES_METADATA:
            self.losses = _losses(rec.metadata)

    def on_metadata(self, rec: Metadata) -> None:
        """The scenario metadata record (a fallback for the meta/scenario message)."""
        for k, v in metadata_fields(rec.metadata).items():
            self.meta.setdefault(k, v)

    # -- messages by kind -----------------------------------------------------------------
    def on_message(self, msg: Message) -> None:
        ch = self.channels.get(msg.channel_id)
        if ch is None:
            return
        self.n_messages += 1
        self.log_ns = int(msg.log_time)
        if ch.topic == RAW_TOPIC:
            self.on_raw(msg)
            return
        try:
            _, kind, name = keys.split(ch.topic)
            obj = json.loads(msg.data)
        except ValueError:
            return
        handler = {
            "meta": self.on_meta,
            "command": self.on_command,
            "status": self.on_status,
            "control": self.on_control,
        }.get(kind)
        if handler is not None:
            handler(name, obj)

    def on_raw(self, msg: Message) -> None:
        """A vehicle MAVLink frame: telemetry of the track and the run's end."""
        m = _decode_frame(self.parser, bytes(msg.data))
        if m is not None:
            self.evidence.on_mavlink(m, self.log_ns)
            if m.get_msgId() not in TRACK_IDS:
                return
            if self.paced is not None:
                self.paced.add(m, self.log_ns)
            else:
                self.steps.add(m)

    def on_meta(self, name: str, obj) -> None:
        if name == SCENARIO_META and isinstance(obj, dict):
            self.meta.update(obj)
            clock = paced_clock(obj) if self.paced is None else None
            self.evidence.paced = obj.get("pacing") == "vehicle"
            if clock is not None:
                self.paced = _PacedSteps(LocalFrame(clock.origin_lat, clock.origin_lon), clock.dt)
        elif name == "clock" and isinstance(obj, dict) and self.paced is not None:
            self.start_ms = int(obj.get("start_ms", 0))
            self.paced.begin(self.start_ms)
            self.evidence.on_clock(self.start_ms)

    def on_command(self, name: str, obj) -> None:
        """A back-seat set-point of source ``name``, by the step (tick) it answers."""
        if isinstance(obj, dict):
            self.evidence.on_setpoint(name, self.log_ns)
        if isinstance(obj, dict) and obj.get("tick_ms") is not None:
            self.command_log_ns.setdefault(name, {}).setdefault(int(obj["tick_ms"]), self.log_ns)
            self.commands.setdefault(name, {})[int(obj["tick_ms"])] = (
                float(obj["vx"]),
                float(obj["vy"]),
                float(obj["vz"]),
                float(obj["yaw"]),
            )

    def on_status(self, name: str, obj) -> None:
        if not isinstance(obj, dict):
            return
        if name in ("referee", keys.BRINGUP_SOURCE, keys.WATCHDOG_SOURCE):
            self.events.append({"source": name, **obj})
            self.evidence.on_event(name, obj)
            if name == "referee" and self.paced is not None and obj.get("ended"):
                self.paced.ended = str(obj["ended"])
        else:
            self.status[name] = obj

    def on_control(self, name: str, obj) -> None:
        """Which back-seat source the bridge obeys: the last one that flew the scenario, not the
        bring-up's or the watchdog's (they take over before and after it)."""
        if name == "active":
            value = str(obj.get("value", obj)) if isinstance(obj, dict) else str(obj)
            if value not in (keys.BRINGUP_SOURCE, keys.WATCHDOG_SOURCE):
                self.active = value

    # -- set-points ---------------------------------------------------------------------
    def _setpoint_delay(self, rows: np.ndarray, source: str | None, setpoints: np.ndarray) -> np.ndarray:
        """Per step, vehicle seconds until the set-point answering it reached the bus (see :class:`LoggedRun`).

        A vehicle-paced front-seat flies the previous set-point until the next arrives (and
        stops 3 s after the last one): a step answered late, or not at all, was not flown
        on its logged set-point.  Bus arrival times (log time) are put on the vehicle's
        clock through the log times of the reports that opened the steps.
        """
        n = rows.shape[0]
        delay = np.where(np.isfinite(setpoints[:, 1]), 0.0, np.nan) if n else np.zeros(0)
        paced = self.paced
        if paced is None or source is None or not n or len(paced.row_log_ns) != n:
            return delay
        first = self.command_log_ns.get(source, {})
        step_ms = np.round(rows[:, 0] * 1000).astype(np.int64) + self.start_ms
        wall = np.array(paced.row_log_ns, dtype=float)
        for k in range(n):
            if not np.isfinite(setpoints[k, 1]):
                continue
            at = first.get(int(step_ms[k]))
            if at is None:  # the back-seat did not answer this step: the vehicle flew an older set-point
                delay[k] = np.inf
            else:
                delay[k] = max(0.0, float(np.interp(float(at), wall, rows[:, 0])) - rows[k, 0])
        return delay

    def _setpoints(self, rows: np.ndarray) -> tuple[str | None, np.ndarray]:
        """The source flown (the active one, else the one with most set-points) and, per step, the
        set-point the front-seat flew after it (NaN where none)."""
        commands, active = self.commands, self.active
        source = active if active in commands else (max(commands, key=lambda k: len(commands[k])) if commands else None)
        setpoints = np.full((rows.shape[0], 3), np.nan)
        if source is not None and rows.shape[0]:
            table = commands[source]
            ticks = np.array(sorted(table))
            values = np.array([table[k] for k in ticks], dtype=np.float32)
            step_ms = np.round(rows[:, 0] * 1000).astype(np.int64) + self.start_ms
            # the set-point the front-seat flew after each step: the latest one issued for a tick <= this step
            idx = np.searchsorted(ticks, step_ms, side="right") - 1
            ok = idx >= 0
            h, s, up = decode_command(values[idx[ok], 0], values[idx[ok], 1], values[idx[ok], 2], values[idx[ok], 3])
            setpoints[ok] = np.column_stack([h, s, up.astype(float)])
        elif rows.shape[0]:
            self.problems.append(
                "no back-seat set-points in the log: the trajectory cannot be replayed for the bias fit"
            )
        return source, setpoints
