"""What a recorded log must have for a closed loop, and which of its streams paces the frames.

:func:`refuse_unfit_log` names what is missing (no ego pose; no objects for reactive agents);
:func:`pace_frames` picks the stream whose messages make the frames (see its docstring for the
rule) and says why.
"""

from __future__ import annotations

import dataclasses

from redrive.assembly.sensor_map import GROUND_TRUTH_DRIVER, SensorMap, SensorMapOverrides
from redrive.errors import ConfigError
from redrive.io import LogReader

__all__ = ["pace_frames", "refuse_unfit_log", "topics_text"]


def topics_text(log: LogReader) -> str:
    return ", ".join(f"{t} ({i.msgtype})" for t, i in sorted(log.topics.items())) or "none"


def refuse_unfit_log(log: LogReader, *, agents: str) -> None:
    """Refuse a log closed loop cannot run on, naming what is missing.

    Raises:
        ConfigError: no ego pose; ``agents == "reactive"`` and no objects.
    """
    if not log.capabilities.has_ego_pose:
        msg = (
            f"{log.path}: closed loop needs the ego's pose (odometry/poses); this log has none "
            f"— its topics: {topics_text(log)}"
        )
        raise ConfigError(msg)
    if agents == "reactive" and not log.capabilities.has_ground_truth:
        msg = (
            f"{log.path}: --agents reactive needs the other road users (ground-truth objects or "
            f"tracks); this log has none — its topics: {topics_text(log)}. Use --agents replay"
        )
        raise ConfigError(msg)


def pace_frames(
    log: LogReader,
    smap: SensorMap,
    *,
    overrides: SensorMapOverrides | None,
    reads_sensors: bool,
) -> tuple[SensorMap, str]:
    """The sensor map with the stream that paces the frames as its ``driver`` (None: the
    ground truth), and why that one.

    The rule: a ``driver`` the sensor map file names wins (a sensor, or ``"ground_truth"``);
    else, when no stage reads a sensor (an object-level run: the frames the algorithms use are
    the ego state and the objects) and the log has ground truth, the ground truth paces — the
    sensors' samples are then attached to the nearest ground-truth frame where one is near,
    as in replay; else the sensor map's driver (its highest-rate LiDAR, camera, 2D LiDAR or
    radar), else the busiest sensor (IMU, GNSS …); else the ground truth.
    """
    named = overrides.driver if overrides is not None else None
    if named == GROUND_TRUTH_DRIVER:
        return smap, f'the sensor map says driver = "{GROUND_TRUTH_DRIVER}"'
    if named is not None:
        return smap, "the sensor map names it as the driver"
    has_truth = smap.ground_truth_topic is not None
    if not reads_sensors and has_truth:
        why = "no stage reads a sensor: an object-level run is paced by its ground truth"
        return dataclasses.replace(smap, driver=None), why
    if smap.driver is not None:
        return smap, "a stage reads a sensor: the log's highest-rate LiDAR/camera/radar paces"
    if smap.sensors:
        busiest = max(smap.sensors, key=lambda s: (s.rate_hz, s.sensor_id))
        why = "the log has no LiDAR, camera or radar: its busiest sensor paces"
        if has_truth:
            why = (
                "a stage reads a sensor and the log has no LiDAR, camera or radar: its busiest "
                "sensor paces"
            )
        return dataclasses.replace(smap, driver=busiest.sensor_id), why
    if not has_truth:
        msg = (
            f"{log.path}: closed loop needs a sensor topic or ground truth to pace its "
            "frames (a LiDAR, camera, radar, IMU or GNSS, or objects); this log has none "
            f"— its topics: {topics_text(log)}"
        )
        raise ConfigError(msg)
    return smap, "the log has no sensor: its ground truth paces (recorded traffic)"
