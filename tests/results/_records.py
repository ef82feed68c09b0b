"""Hand-built frame records for the results tests (every output kind, errors, ground truth)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from redrive.results import (
    AlgorithmEntry,
    ClosedLoopRecord,
    FrameRecord,
    PipelineInfo,
    ResourceSample,
    RunSetup,
    SourceLog,
    StepRecord,
)
from redrive.types import (
    Box3D,
    ControlCommands,
    DetectedObject,
    LightState,
    ObjectClass,
    PlannedPath,
    Role,
    TrafficLight,
    VehicleState,
)

T0_NS = 1_700_000_000_123_456_789
EVIL = '=HYPERLINK("http://x")'

SETUP = RunSetup(
    log=SourceLog(path="/data/drive.mcap", sha256="abc", format="mcap"),
    seed=7,
    pipeline=PipelineInfo(first_frame=0, stages=("p", "c")),
    algorithms=(
        AlgorithmEntry(name="det", version="1", config_hash="c1", role=Role.PERCEPTION),
        AlgorithmEntry(name="bad_det", version="1", config_hash="c2", role=Role.PERCEPTION),
        AlgorithmEntry(name="planner", version="2", config_hash="c3", role=Role.PLANNING),
        AlgorithmEntry(name="ctrl", version="1", config_hash="c4", role=Role.CONTROL),
    ),
)


def detection(i: int, k: int, *, bbox: bool) -> DetectedObject:
    return DetectedObject(
        object_id=100 * i + k,
        object_class=(ObjectClass.VEHICLE, ObjectClass.PEDESTRIAN, ObjectClass.BICYCLE)[k % 3],
        confidence=0.5 + 0.1 * k,
        box=Box3D(
            center=np.array([10.0 + i / 3, -2.5 * k, 0.75]),
            size=np.array([4.5, 1.9, 1.6 + k / 7]),
            yaw_rad=0.1 * k - 0.05,
        ),
        velocity=np.array([1.0 / 3, -0.2, 0.0]),
        acceleration=np.array([0.0, 0.01 * i, -1e-300]),
        bbox_2d=(10.5 * k, 20.0, 33.3, 44.4) if bbox else None,
    )


def gt_object(i: int, k: int) -> DetectedObject:
    return DetectedObject(
        object_id=k,
        object_class=ObjectClass.VEHICLE if k == 0 else ObjectClass.PEDESTRIAN,
        box=Box3D(center=np.array([12.0 - i, 3.0 * k, 0.8]), size=np.array([4.0, 2.0, 1.5])),
        velocity=np.array([-1.0, 0.0, 0.0]),
        num_lidar_points=None if k == 1 else 40 + i,
        visible=None if k == 1 else bool(i % 2),
    )


def frame(i: int, *, planning: bool = True, long_traceback: str = "") -> FrameRecord:
    """Frame ``i``: det finds i % 3 objects, bad_det fails on even frames, a 5-point path,
    commands; ground truth None every 5th frame (i % 5 == 4), empty when i % 5 == 3; two
    traffic lights but on frame 2 (light "w" red on odd frames, "s" green)."""
    stamp = T0_NS + i * 100_000_000
    dets = tuple(detection(i, k, bbox=k % 2 == 0) for k in range(i % 3))
    steps = [
        StepRecord(
            algorithm="det",
            stage="perception",
            role="perception",
            status="ok",
            latency_ns=1_000_000 + i,
            cpu_ns=900_000,
            output=dets,
        )
    ]
    if i % 2 == 0:
        steps.append(
            StepRecord(
                algorithm="bad_det",
                stage="perception",
                role="perception",
                status="error",
                latency_ns=50_000,
                cpu_ns=40_000,
                error_type="ZeroDivisionError",
                error_message=EVIL,
                traceback=long_traceback or 'Traceback (most recent call last):\n  File "x.py"\n',
            )
        )
    else:
        steps.append(
            StepRecord(
                algorithm="bad_det", stage="perception", role="perception", status="ok", output=()
            )
        )
    if planning:
        t = np.linspace(0.0, 2.0, 5)
        wp = np.column_stack([t * 5.0, np.sin(t) + i, np.zeros(5), t])
        path = PlannedPath(stamp_ns=stamp, waypoints=wp, frame_id="base_link")
        steps.append(
            StepRecord(
                algorithm="planner",
                stage="planning",
                role="planning",
                status="ok",
                latency_ns=3_000_000,
                cpu_ns=2_500_000,
                output=path,
            )
        )
        steps.append(
            StepRecord(
                algorithm="ctrl",
                stage="control",
                role="control",
                status="ok" if i != 1 else "skipped",
                latency_ns=10_000,
                output=ControlCommands(throttle=0.25, brake=0.0, steering_angle_rad=-0.01 * i)
                if i != 1
                else None,
            )
        )
    if i % 5 == 4:
        gt: tuple[DetectedObject, ...] | None = None
    elif i % 5 == 3:
        gt = ()
    else:
        gt = (gt_object(i, 0), gt_object(i, 1))
    ego = VehicleState(
        stamp_ns=stamp,
        frame_id="map",
        position=np.array([512_345.678 + i, 5_412_345.125, 101.5]),
        velocity=np.array([8.0, 0.5, 0.0]),
        acceleration=np.array([0.1, 0.0, 0.0]),
        heading_rad=0.3,
        yaw_rate_rad_s=0.01,
    )
    logged = (  # a closed-loop run keeps the logged ego apart: here on odd frames, 1 m behind
        replace(ego, position=ego.position - np.array([1.0, 0.0, 0.0])) if i % 2 else None
    )
    closed = (  # ... and what moved the ego after the frame (the fallback on frame 3)
        None
        if logged is None
        else ClosedLoopRecord(
            source="fallback" if i == 3 else "tracker",
            algorithm="" if i == 3 else "planner",
            reason="planner: an empty path" if i == 3 else "",
            throttle=0.0 if i == 3 else 0.25,
            brake=1.0 if i == 3 else 0.0,
            steering_angle_rad=0.01 * i,
            deviation_m=1.0,
            deviation_yaw_rad=0.0,
        )
    )
    return FrameRecord(
        frame_index=i,
        stamp_ns=stamp,
        steps=tuple(steps),
        vehicle_state=ego,
        logged_vehicle_state=logged,
        closed_loop=closed,
        ground_truth=gt,
        traffic_lights=()
        if i == 2
        else (
            TrafficLight(id="w", state=LightState.RED if i % 2 else LightState.GREEN),
            TrafficLight(id="s", state=LightState.GREEN),
        ),
        wall_ns=5_000_000,
        late=i == 2,
    )


def resources(n: int) -> list[ResourceSample]:
    return [
        ResourceSample(t_ns=T0_NS + k, label="engine", pid=1234, cpu_percent=12.5, rss_bytes=2**30)
        for k in range(n)
    ]


def same_object(a: DetectedObject, b: DetectedObject) -> bool:
    """Equal in every stored field (orientation is not stored)."""
    return (
        a.object_id == b.object_id
        and a.object_class == b.object_class
        and a.confidence == b.confidence
        and np.array_equal(a.box.center, b.box.center)
        and np.array_equal(a.box.size, b.box.size)
        and a.box.yaw_rad == b.box.yaw_rad
        and np.array_equal(a.velocity, b.velocity)
        and np.array_equal(a.acceleration, b.acceleration)
        and a.bbox_2d == b.bbox_2d
        and a.num_lidar_points == b.num_lidar_points
        and a.visible == b.visible
    )
