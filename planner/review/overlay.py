"""What ``rapt-plan compare`` leaves for Foxglove: per flown scenario, observed and predicted tracks overlaid.

One MCAP per flown scenario, ``overlay_<scenario>.mcap`` next to ``comparison.json``, that
Foxglove's Map panel draws with no configuration (:mod:`bridge.foxglove`'s well-known
schemas):

=============================  ======================  ==============================================
topic                          schema                  what
=============================  ======================  ==============================================
``/map/scenario``              ``foxglove.GeoJSON``    the scenario's mission elements (areas, no-go
                                                       areas, launch and recovery points)
``/map/observed``              ``foxglove.GeoJSON``    each logged run's track (a LineString per log)
``/map/predicted``             ``foxglove.GeoJSON``    the plan's prediction
``/map/corrected``             ``foxglove.GeoJSON``    the prediction under the bias compare used
                                                       (the uncorrected one when the logs do not
                                                       support a correction: see its properties)
``/map/calibrated``            ``foxglove.GeoJSON``    with a calibrated vehicle only
``/fix/observed/<log>``        ``foxglove.LocationFix`` the same tracks as positions over time, so
``/fix/predicted`` ...                                 playback moves them side by side
``/checks``                    ``foxglove.Log``        each run's automatic checks that did not pass
                                                       (:mod:`planner.review.run_checks`), at the time
                                                       of their evidence, named after the log
=============================  ======================  ==============================================

Log time is scenario time (seconds since the run's start, from the epoch): the runs of one
scenario, flown on different days, line up. The GeoJSON documents are at time 0.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from bridge import foxglove
from bridge.mcap_channels import McapChannels
from planner.common.geojson import geojson
from sim.uuv.geo import LocalFrame
from sim.uuv.mission import Mission

__all__ = ["overlay_name", "write_overlay"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_.\-]")


def overlay_name(sid: str) -> str:
    """``overlay_<scenario id>.mcap`` (characters unsafe in a file name replaced by ``_``)."""
    return f"overlay_{_UNSAFE.sub('_', sid)}.mcap"  # planner.review.compare.OVERLAY_PREFIX: refused as an input there


def write_overlay(
    path: str | Path,
    mission: Mission,
    u,
    observed: list[tuple[str, np.ndarray]],
    tracks: dict[str, np.ndarray | None],
    properties: dict | None = None,
    checks: list[tuple[str, list[dict]]] | None = None,
) -> Path:
    """Write scenario ``u``'s overlay (see the module docstring) to ``path``.

    ``observed``: (log name, track) per logged run, tracks with columns t, x, y first
    (:data:`sim.uuv.replay.TRACK_FIELDS`); ``tracks``: predicted, corrected, calibrated
    trajectories by name (None: not available); ``properties`` go on the corrected track; ``checks``:
    (log name, its run checks as dicts) per logged run.
    """
    frame = LocalFrame(mission.origin_lat, mission.origin_lon)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        writer = Writer(f, compression=CompressionType.ZSTD)
        writer.start(profile="", library="rapt-compare")
        mcap = McapChannels(writer)

        def add(topic: str, schema_name: str, message: dict, ns: int) -> None:
            mcap.add_foxglove(topic, schema_name, message, ns, ns)

        add("/map/scenario", "foxglove.GeoJSON", foxglove.geojson_message(geojson(mission, u)), 0)
        observed = [(name, t) for name, t in observed if t.shape[0] >= 2]  # a line needs two points
        drawn = {kind: t for kind, t in tracks.items() if t is not None and t.shape[0] >= 2}
        lines = [_line(frame, track, {"kind": "observed", "name": name}) for name, track in observed]
        add("/map/observed", "foxglove.GeoJSON", foxglove.geojson_message(_collection(lines)), 0)
        for kind, track in drawn.items():
            props = {"kind": kind, "name": kind}
            if kind == "corrected":
                props.update(properties or {})
            doc = _collection([_line(frame, track, props)])
            add(f"/map/{kind}", "foxglove.GeoJSON", foxglove.geojson_message(doc), 0)
        series = [(f"/fix/observed/{_UNSAFE.sub('_', name)}", t) for name, t in observed]
        series += [(f"/fix/{kind}", t) for kind, t in drawn.items()]
        fixes = []
        for topic, track in series:
            lat, lon = frame.to_latlon(track[:, 1], track[:, 2])
            ns = np.round(track[:, 0] * 1e9).astype(np.int64)
            fixes += [
                (int(n), topic, float(a), float(b)) for n, a, b in zip(ns, np.atleast_1d(lat), np.atleast_1d(lon))
            ]
        records = [
            (n, topic, "foxglove.LocationFix", foxglove.location_fix(a, b, 0.0, n, frame_id=topic))
            for n, topic, a, b in fixes
        ]
        records += _check_events(checks or [])
        for n, topic, schema_name, message in sorted(records, key=lambda r: (r[0], r[1])):  # in time order
            add(topic, schema_name, message, n)
        writer.finish()
    return path


#: foxglove.LogLevel of a check's verdict (a pass is not logged).
CHECK_LEVEL = {"warn": foxglove.WARNING, "unknown": foxglove.WARNING, "fail": foxglove.ERROR}


def _check_events(checks: list[tuple[str, list[dict]]]) -> list[tuple[int, str, str, dict]]:
    """Each check that did not pass as a ``foxglove.Log`` line on ``/checks`` at its evidence's time."""
    out = []
    for name, run_checks in checks:
        for c in run_checks:
            if c["verdict"] in CHECK_LEVEL:
                n = int(round(float(c.get("time_s") or 0.0) * 1e9))
                text = f"{c['name']} {c['verdict']}: {c['reason']}"
                out.append(
                    (n, "/checks", "foxglove.Log", foxglove.log_message(CHECK_LEVEL[c["verdict"]], text, name, n))
                )
    return out


def _line(frame: LocalFrame, track: np.ndarray, properties: dict) -> dict:
    """A GeoJSON LineString Feature of a track's (x, y) columns, ``[lon, lat]`` pairs."""
    lat, lon = frame.to_latlon(track[:, 1], track[:, 2])
    coords = [[float(b), float(a)] for a, b in zip(np.atleast_1d(lat), np.atleast_1d(lon))]
    t = track[:, 0]
    props = {**properties, "duration_s": float(t[-1] - t[0]) if len(t) else 0.0}
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": coords}, "properties": props}


def _collection(features: list[dict]) -> dict:
    return {"type": "FeatureCollection", "features": features}
