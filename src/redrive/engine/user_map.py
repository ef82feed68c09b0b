"""``--map FILE`` for any log: the road map a run uses, where it came from, and how it was placed.

A run's road map is, in this order: none when the user said ``--no-map``; the user's map file
(``--map``: Lanelet2 ``.osm``, Argoverse 2 ``log_map_archive_*.json``, a run's ``map.json``, or a
log whose reader gives a map — a CommonRoad scenario ``.xml``, an Argoverse 2 log folder); else
the log's own map (its reader's ``road_map`` capability).  A user map beside a log's own wins,
with a warning.

The user's map is placed in the log's frame (:func:`align_map`):

* the ego's poses are in ``map`` (Autoware: ``/localization/kinematic_state`` in ``map``): the
  map's coordinates are taken as they are — alignment ``log map frame``;
* the ego is in another frame (``odom``) and the log's tf links ``map`` to it: the map is moved
  by the planar part of ``odom ← map`` at the log's first stamp — alignment ``tf``; a ``map →
  odom`` that changes later (localisation corrections) is said in a warning;
* the log has no ``map`` frame: with ``--map-origin LAT,LON`` (a Lanelet2 map projected about it)
  the ego's frame is taken to be the map's projection frame, with a warning — alignment
  ``origin``; without it, :class:`~redrive.errors.MapError` says what to pass.

The manifest's ``map`` entry (:func:`choose_road_map` → :attr:`ChosenMap.record`) records the
file (path, format, sha256, size), the origin, the alignment and what it replaced.  A Lanelet2
map (its nodes carry latitude and longitude) is checked against the log's first GNSS fix, when
the log has one: a map far from where the log was recorded is said in a warning and in the
entry's ``gnss`` (:func:`gnss_check`).
"""

from __future__ import annotations

import hashlib
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from redrive.assembly.sensor_map import SensorMap
from redrive.assembly.tf_buffer import TransformBuffer, TransformLookupError
from redrive.errors import LogError, MapError, UnsupportedMessageError
from redrive.io import LogReader, open_log
from redrive.io.content import log_road_map
from redrive.io.ros.decoders import decode, decoder_for
from redrive.maps.files import map_format, read_map_file
from redrive.maps.moved import moved_map
from redrive.types import GnssFix, RoadMap, SensorType, Transform, VehicleState

__all__ = [
    "ChosenMap",
    "MapOption",
    "align_map",
    "attach_map",
    "choose_road_map",
    "manifest_frames",
    "read_user_map",
]

logger = logging.getLogger(__name__)

#: how far into the log its tf is read to find the frames (messages per tf topic)
_TF_MESSAGES = 200
_NO_MAP_ADVICE = "or run with --no-map to run the log without the map metrics"


@dataclass(frozen=True, slots=True, kw_only=True)
class MapOption:
    """What the user said of the road map.

    Attributes:
        path: ``--map FILE``; None: the log's own map, if any.
        origin_lat_lon: ``--map-origin LAT,LON`` (degrees): a Lanelet2 map's projection origin.
        disabled: ``--no-map``: no road map at all (the log's own neither); the map metrics are
            skipped with that reason.
    """

    path: Path | None = None
    origin_lat_lon: tuple[float, float] | None = None
    disabled: bool = False

    def __post_init__(self) -> None:
        if self.disabled and self.path is not None:
            msg = "--no-map and --map exclude each other: give one"
            raise MapError(msg)


@dataclass(frozen=True, slots=True, kw_only=True)
class ChosenMap:
    """The road map of a run (None: none) and the manifest's ``map`` entry describing it."""

    road_map: RoadMap | None
    record: Mapping[str, Any] = field(default_factory=dict)


def _sha256(path: Path) -> tuple[str, int]:
    digest = hashlib.sha256()
    size = 0
    with path.open("rb") as fh:
        while chunk := fh.read(1 << 20):
            digest.update(chunk)
            size += len(chunk)
    return digest.hexdigest(), size


def read_user_map(option: MapOption) -> tuple[RoadMap, dict[str, Any]]:
    """The map of ``option.path`` and what the manifest says of its file (path, format, sha256,
    size, origin).

    Raises:
        MapError: not a map redrive reads, or damaged (the message names the element and says
            ``--no-map`` runs the log without it).
    """
    assert option.path is not None
    file = Path(option.path)
    if not file.exists():
        msg = f"--map {file}: no such file"
        raise MapError(msg)
    fmt = map_format(file)
    try:
        if fmt is not None:
            road_map = read_map_file(file, origin_lat_lon=option.origin_lat_lon)
        else:
            road_map, fmt = _map_of_log(file)
    except MapError as err:
        raise MapError(f"{err}; {_NO_MAP_ADVICE}") from err
    if option.origin_lat_lon is not None and fmt != "lanelet2":
        logger.warning(
            "--map-origin is for a Lanelet2 map's projection; %s is a %s map in metres and "
            "ignores it",
            file,
            fmt,
        )
    sha, size = _sha256(file) if file.is_file() else (None, None)
    record: dict[str, Any] = {
        "path": str(file.resolve()),
        "format": fmt,
        "sha256": sha,
        "size_bytes": size,
        "origin_lat_lon": None if option.origin_lat_lon is None else list(option.origin_lat_lon),
        "source": road_map.source,
        "lanes": len(road_map.lanes),
    }
    return road_map, record


def _map_of_log(file: Path) -> tuple[RoadMap, str]:
    """The map inside a log that carries one (a CommonRoad scenario, an AV2 log folder)."""
    try:
        with open_log(file) as log:
            road_map = log_road_map(log)
            fmt = log.format
    except (LogError, OSError) as err:
        msg = (
            f"{file}: not a map file redrive reads (Lanelet2 .osm, Argoverse 2 "
            f"log_map_archive_*.json, a run's map.json, a CommonRoad scenario .xml): {err}"
        )
        raise MapError(msg) from err
    if road_map is None:
        msg = f"{file}: a {fmt} log that holds no road map"
        raise MapError(msg)
    return road_map, fmt


def _ego_frame(log: LogReader, topic: str | None) -> str | None:
    """The frame of the ego's first pose on ``topic`` (None: no such topic or no pose)."""
    if topic is None:
        return None
    for message in log.messages(topics=[topic]):
        if decoder_for(message.msgtype) is None and message.encoding != "native":
            return None
        try:
            value = decode(message, log.deserialize).value
        except UnsupportedMessageError:
            continue
        if isinstance(value, VehicleState):
            return value.frame_id.lstrip("/") or None
        return None
    return None


def _log_tf(log: LogReader, topics: tuple[str, ...]) -> tuple[TransformBuffer, int | None, bool]:
    """The log's first transforms (:data:`_TF_MESSAGES` a topic): the buffer, the first stamp,
    and whether an edge at ``map`` moves (a dynamic ``map → odom``)."""
    buffer = TransformBuffer(window_ns=1 << 62, tolerance_ns=1 << 62)
    first: int | None = None
    moving = False
    seen: dict[str, tuple[float, ...]] = {}
    for topic in topics:
        static = "static" in topic
        for count, message in enumerate(log.messages(topics=[topic])):
            if count >= _TF_MESSAGES:
                break
            try:
                decoded = decode(message, log.deserialize)
            except UnsupportedMessageError:
                continue
            values = decoded.value if isinstance(decoded.value, tuple) else ()
            for t in values:
                if not isinstance(t, Transform):
                    continue
                buffer.add(t, static=static)
                first = t.stamp_ns if first is None else min(first, t.stamp_ns)
                if "map" in (t.parent_frame.lstrip("/"), t.child_frame.lstrip("/")):
                    key = f"{t.parent_frame}>{t.child_frame}"
                    pose = (*t.translation.tolist(), *t.rotation.tolist())
                    old = seen.setdefault(key, pose)
                    moving |= any(abs(a - b) > 1e-3 for a, b in zip(old, pose, strict=True))
    return buffer, first, moving


def align_map(
    road_map: RoadMap,
    log: LogReader,
    *,
    sensor_map: SensorMap,
    origin_lat_lon: tuple[float, float] | None = None,
) -> tuple[RoadMap, dict[str, Any]]:
    """``road_map`` placed in the frame of ``log``'s ego, and the manifest's ``alignment``
    (see the module text).

    Raises:
        MapError: the log has no ``map`` frame and no origin was given (the message says what
            to pass).
    """
    ego_frame = _ego_frame(log, sensor_map.vehicle_state_topic)
    where = f" (ego poses on {sensor_map.vehicle_state_topic})" if ego_frame else ""
    if ego_frame == "map":
        return road_map, {"method": "log map frame", "frame": "map", "detail": f"ego in map{where}"}
    buffer, first_ns, moving = _log_tf(log, sensor_map.tf_topics)
    if ego_frame is None and "map" in buffer.frames:  # no ego pose: the log's frames are map's
        return road_map, {"method": "log map frame", "frame": "map", "detail": "map in tf"}
    target = ego_frame
    if "map" in buffer.frames and target is not None and target in buffer.frames:
        stamp = log.start_ns if first_ns is None else first_ns
        try:
            mat = buffer.lookup(target, "map", stamp)
        except TransformLookupError:
            mat = None
        if mat is not None:
            yaw = math.atan2(float(mat[1, 0]), float(mat[0, 0]))
            shift = (float(mat[0, 3]), float(mat[1, 3]))
            if moving:
                logger.warning(
                    "%s: the log's map → %s transform changes over the log; the map is placed "
                    "with its first value (at %d ns)",
                    log.path,
                    target,
                    stamp,
                )
            placed = moved_map(road_map, yaw_rad=yaw, translation_xy=shift, frame_id=target)
            return placed, {
                "method": "tf",
                "frame": target,
                "detail": f"{target} <- map from the log's tf at {stamp} ns{where}",
                "yaw_rad": yaw,
                "translation_m": list(shift),
                "changes_over_log": moving,
            }
    frames = sorted(buffer.frames | ({ego_frame} if ego_frame else set()))
    said = ", ".join(frames) if frames else "none"
    if origin_lat_lon is None:
        msg = (
            f"{log.path}: the log has no `map` frame (the ego is in "
            f"{ego_frame or 'no frame: no ego pose'}; tf frames: {said}), so redrive cannot tell "
            "where the map lies in it. Pass --map-origin LAT,LON — the latitude and longitude "
            f"of the origin of the log's {ego_frame or 'world'} frame, about which the map is "
            "projected — or record the log with its map → odom transform on /tf; "
            f"{_NO_MAP_ADVICE}"
        )
        raise MapError(msg)
    frame = ego_frame or road_map.frame_id
    logger.warning(
        "%s has no `map` frame: its %s frame is taken to be the map projected about lat %s, "
        "lon %s (--map-origin)",
        log.path,
        frame,
        origin_lat_lon[0],
        origin_lat_lon[1],
    )
    placed = road_map if frame == road_map.frame_id else replace(road_map, frame_id=frame)
    return placed, {
        "method": "origin",
        "frame": frame,
        "detail": f"no map frame in the log; its {frame} frame is the map projected about the "
        "given origin" + where,
    }


def choose_road_map(
    log: LogReader, option: MapOption | None, *, sensor_map: SensorMap
) -> ChosenMap:
    """The road map of a run of ``log`` and the manifest's ``map`` entry (module text).

    Raises:
        MapError: the user's map cannot be read or placed, or the log's own map is damaged
            (each message says ``--no-map`` runs the log without it).
    """
    option = option or MapOption()
    if option.disabled:
        return ChosenMap(road_map=None, record={"disabled": True, "from": "--no-map"})
    try:
        own = log_road_map(log)
    except MapError as err:
        if option.path is None:
            raise MapError(f"{err}; {_NO_MAP_ADVICE}") from err
        own = None
        logger.warning("%s: its own map cannot be read (%s); --map replaces it", log.path, err)
    if option.path is None:
        if own is None:
            return ChosenMap(road_map=None)
        return ChosenMap(road_map=own, record={"from": "log", "source": own.source})
    road_map, record = read_user_map(option)
    placed, alignment = align_map(
        road_map, log, sensor_map=sensor_map, origin_lat_lon=option.origin_lat_lon
    )
    record = {"from": "--map", **record, "alignment": alignment}
    if record.get("format") == "lanelet2" and (
        far := gnss_check(log, sensor_map, road_map, Path(option.path))
    ):
        record["gnss"] = far
    if own is not None and _same_file(own.source, Path(option.path)):
        record["same_as_log"] = True  # the log's own map file given again: nothing replaced
    elif own is not None:
        logger.warning(
            "%s carries its own road map (%s); the map given with --map (%s) is used instead",
            log.path,
            own.source or log.format,
            option.path,
        )
        record["replaced"] = own.source or f"the {log.format} log's own map"
    return ChosenMap(road_map=placed, record=record)


def attach_map(run_dir: Path, option: MapOption) -> dict[str, Any]:
    """Give the existing run in ``run_dir`` the map of ``option`` (``evaluate --map``, ``gui
    --map``): read, placed through the run's log (as :func:`choose_road_map` does), written to
    ``RUN/map.json`` (a map the run had is replaced, with a warning) and recorded in the
    manifest's ``map``; returns that entry.

    Raises:
        MapError: as :func:`choose_road_map`; the run's log is gone and no origin was given.
        ConfigError: not a run directory.
    """
    from redrive.assembly.sensor_map import infer_sensor_map
    from redrive.results import MAP_NAME, write_road_map
    from redrive.results.manifest import read_manifest, write_manifest

    assert option.path is not None
    manifest = read_manifest(run_dir)
    road_map, record = read_user_map(option)
    log_path = Path(manifest.log.path)
    if log_path.exists():
        with open_log(log_path, strict=False) as log:
            smap = infer_sensor_map(log.topics, duration_ns=log.end_ns - log.start_ns)
            placed, alignment = align_map(
                road_map, log, sensor_map=smap, origin_lat_lon=option.origin_lat_lon
            )
            if record.get("format") == "lanelet2" and (
                far := gnss_check(log, smap, road_map, Path(option.path))
            ):
                record["gnss"] = far
    elif option.origin_lat_lon is not None:
        frame = next(iter(manifest_frames(run_dir)), road_map.frame_id)
        logger.warning(
            "%s: the run's log %s is gone; the run's %s frame is taken to be the map projected "
            "about the given origin",
            run_dir,
            log_path,
            frame,
        )
        placed = replace(road_map, frame_id=frame)
        alignment = {"method": "origin", "frame": frame, "detail": "the run's log is gone"}
    else:
        msg = (
            f"{run_dir}: the run's log {log_path} is gone, so redrive cannot place the map in its "
            "frames; pass --map-origin LAT,LON (the origin of the ego's frame) or move the log back"
        )
        raise MapError(msg)
    had = manifest.road_map.get("path") or manifest.road_map.get("source")
    if (Path(run_dir) / MAP_NAME).is_file() and _same_file(had, Path(option.path)):
        record["same_as_log"] = manifest.road_map.get("from") == "log" or bool(
            manifest.road_map.get("same_as_log")
        )
    elif (Path(run_dir) / MAP_NAME).is_file():
        logger.warning(
            "%s has a road map (%s); the map given with --map (%s) replaces it",
            run_dir,
            manifest.road_map.get("path") or manifest.road_map.get("source") or "the log's own",
            option.path,
        )
        record["replaced"] = str(
            manifest.road_map.get("path") or manifest.road_map.get("source") or "the run's map"
        )
    write_road_map(run_dir, placed)
    entry = {"from": "--map", **record, "alignment": alignment}
    write_manifest(Path(run_dir), replace(manifest, road_map=entry))
    return entry


#: a Lanelet2 map further than this beyond its own extent from the log's GNSS fix is said
FAR_FROM_GNSS_KM = 5.0


def gnss_check(
    log: LogReader, sensor_map: SensorMap, road_map: RoadMap, file: Path
) -> dict[str, Any] | None:
    """The log's first GNSS fix against the Lanelet2 map ``road_map`` read from ``file`` (its
    first node's latitude and longitude, the map's extent in metres): the manifest's ``gnss``
    entry (topic, fix, distance in km, ``far``), with a warning when the fix lies more than
    :data:`FAR_FROM_GNSS_KM` beyond the map's extent; None when the log has no decodable fix."""
    from redrive.maps.lanelet2_osm import first_node

    topics = [s.topic for s in sensor_map.sensors if s.sensor_type is SensorType.GNSS]
    fix = _first_fix(log, topics[0]) if topics else None
    if fix is None or not road_map.lanes:
        return None
    lat, lon, _ = first_node(file)
    # haversine: the great-circle distance on a 6,371-km sphere (good to 0.5 % for this check)
    p1, p2 = math.radians(lat), math.radians(fix.latitude_deg)
    dp, dl = p2 - p1, math.radians(fix.longitude_deg - lon)
    a = math.sin(dp / 2) ** 2 + math.cos(p1) * math.cos(p2) * math.sin(dl / 2) ** 2
    km = 2 * 6371.0 * math.asin(math.sqrt(min(1.0, a)))
    points = np.concatenate([lane.centerline[:, :2] for lane in road_map.lanes])
    extent_km = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))) / 1000.0
    far = km > extent_km + FAR_FROM_GNSS_KM
    if far:
        logger.warning(
            "%s: its GNSS (%s) is at lat %.4f, lon %.4f, %.0f km from the Lanelet2 map (a node at "
            "lat %.4f, lon %.4f; the map spans %.1f km): the map is not of the place this log was "
            "recorded — check --map and --map-origin",
            log.path, topics[0], fix.latitude_deg, fix.longitude_deg, km, lat, lon, extent_km,
        )  # fmt: skip
    return {
        "topic": topics[0],
        "fix_lat_lon": [fix.latitude_deg, fix.longitude_deg],
        "distance_km": round(km, 3),
        "map_extent_km": round(extent_km, 3),
        "far": far,
    }


def _first_fix(log: LogReader, topic: str) -> GnssFix | None:
    """The first decodable fix with a position on ``topic`` (of its first 20 messages)."""
    messages = log.messages(topics=[topic])
    try:
        for tried, message in enumerate(messages):
            if tried >= 20:
                break
            try:
                data = decode(message, log.deserialize).value
            except (UnsupportedMessageError, LogError):
                return None
            if not isinstance(data, GnssFix) or data.status < 0:
                continue
            if math.isfinite(data.latitude_deg) and math.isfinite(data.longitude_deg):
                return data
    finally:
        close = getattr(messages, "close", None)
        if close is not None:
            close()
    return None


def _same_file(source: str | None, file: Path) -> bool:
    """Whether a map's ``source`` (``av2:PATH``, ``lanelet2:PATH (origin …)``, a log's path, or a
    manifest's ``path``) names ``file``."""
    if not source:
        return False
    for candidate in (source, source.split(":", 1)[-1], source.split(":", 1)[-1].split(" (")[0]):
        try:
            if Path(candidate).exists() and Path(candidate).samefile(file):
                return True
        except OSError:
            continue
    return False


def manifest_frames(run_dir: Path) -> list[str]:
    """The frames the run's ego was stored in (first first), from its ``ego`` table."""
    from redrive.results import open_run

    table = open_run(run_dir).table("ego")
    if table.num_rows == 0 or "frame_id" not in table.column_names:
        return []
    return list(dict.fromkeys(str(f) for f in table.column("frame_id").to_pylist() if f))
