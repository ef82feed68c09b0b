"""Records → column buffers → Arrow tables (the write side of the store)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import pyarrow as pa

from redrive.results.records import FrameRecord, ResourceSample, StepRecord
from redrive.results.schema import SCHEMAS
from redrive.types import ControlCommands, DetectedObject, PlannedPath, VehicleState

__all__ = ["TableBuffers"]


class TableBuffers:
    """Column lists per table, filled record by record and emptied by :meth:`take`."""

    def __init__(self) -> None:
        self._cols: dict[str, dict[str, list[Any]]] = {}
        self.n_frames = 0
        self.clear()

    def clear(self) -> None:
        self._cols = {name: {c: [] for c in schema.names} for name, schema in SCHEMAS.items()}
        self.n_frames = 0

    # -- filling -----------------------------------------------------------------------------

    def add_frame(self, rec: FrameRecord) -> None:
        fi, stamp = rec.frame_index, rec.stamp_ns
        gt = rec.ground_truth
        _append(
            self._cols["frames"],
            frame_index=fi,
            stamp_ns=stamp,
            wall_ns=rec.wall_ns,
            late=rec.late,
            n_ground_truth=None if gt is None else len(gt),
            missing_inputs=",".join(rec.missing),
        )
        for step in rec.steps:
            self._add_step(fi, stamp, step)
        if gt:
            cols = self._cols["ground_truth"]
            for obj in gt:
                _append_object(cols, obj)
                cols["frame_index"].append(fi)
                cols["stamp_ns"].append(stamp)
                cols["num_lidar_points"].append(obj.num_lidar_points)
                cols["visible"].append(obj.visible)
        for table, vs in (("ego", rec.vehicle_state), ("ego_logged", rec.logged_vehicle_state)):
            if vs is not None:
                _append_state(self._cols[table], fi, vs)
        cl = rec.closed_loop
        if cl is not None:
            _append(
                self._cols["closed_loop"],
                frame_index=fi,
                stamp_ns=stamp,
                source=cl.source,
                algorithm=cl.algorithm,
                reason=cl.reason,
                throttle=cl.throttle,
                brake=cl.brake,
                steering_angle_rad=cl.steering_angle_rad,
                deviation_m=cl.deviation_m,
                deviation_yaw_rad=cl.deviation_yaw_rad,
                deviated=cl.deviated,
            )
        self.n_frames += 1

    def _add_step(self, fi: int, stamp: int, step: StepRecord) -> None:
        _append(
            self._cols["steps"],
            frame_index=fi,
            stamp_ns=stamp,
            algorithm=step.algorithm,
            stage=step.stage,
            role=step.role,
            status=step.status,
            latency_ns=step.latency_ns,
            cpu_ns=step.cpu_ns,
            n_outputs=step.n_outputs,
            error_type=step.error_type,
            error_message=step.error_message,
            traceback=step.traceback,
        )
        out = step.output
        if isinstance(out, tuple):
            cols = self._cols["detections"]
            for obj in out:
                _append_object(cols, obj)
                cols["algorithm"].append(step.algorithm)
                cols["frame_index"].append(fi)
                cols["stamp_ns"].append(stamp)
                cols["confidence"].append(obj.confidence)
        elif isinstance(out, PlannedPath):
            cols = self._cols["paths"]
            k = out.waypoints.shape[0]
            cols["algorithm"].extend([step.algorithm] * k)
            cols["frame_index"].extend([fi] * k)
            cols["stamp_ns"].extend([out.stamp_ns] * k)
            cols["frame_id"].extend([out.frame_id] * k)
            cols["waypoint"].extend(range(k))
            for j, name in enumerate(("x", "y", "z", "t_s")):
                cols[name].extend(out.waypoints[:, j].tolist())
        elif isinstance(out, ControlCommands):
            _append(
                self._cols["commands"],
                algorithm=step.algorithm,
                frame_index=fi,
                stamp_ns=stamp,
                throttle=out.throttle,
                brake=out.brake,
                steering_angle_rad=out.steering_angle_rad,
            )

    def add_resources(self, samples: Sequence[ResourceSample]) -> None:
        cols = self._cols["resources"]
        for s in samples:
            cols["t_ns"].append(int(s.t_ns))
            cols["label"].append(s.label)
            cols["pid"].append(int(s.pid))
            cols["cpu_percent"].append(float(s.cpu_percent))
            cols["rss_bytes"].append(int(s.rss_bytes))

    # -- emptying ----------------------------------------------------------------------------

    def take(self) -> dict[str, pa.Table]:
        """The buffered rows as one Arrow table per table name (empty ones included); clears."""
        out = {
            name: pa.Table.from_pydict(self._cols[name], schema=schema)
            for name, schema in SCHEMAS.items()
        }
        self.clear()
        return out


def _append(cols: dict[str, list[Any]], **values: Any) -> None:
    for name, value in values.items():
        cols[name].append(value)


def _append_state(cols: dict[str, list[Any]], fi: int, vs: VehicleState) -> None:
    """One row of the ``ego`` or ``ego_logged`` table."""
    cols["frame_index"].append(fi)
    cols["stamp_ns"].append(vs.stamp_ns)
    cols["frame_id"].append(vs.frame_id)
    for names, vec in (
        (("x", "y", "z"), vs.position),
        (("vx", "vy", "vz"), vs.velocity),
        (("ax", "ay", "az"), vs.acceleration),
    ):
        for name, value in zip(names, vec.tolist(), strict=True):
            cols[name].append(value)
    cols["heading_rad"].append(vs.heading_rad)
    cols["yaw_rate_rad_s"].append(vs.yaw_rate_rad_s)


def _append_object(cols: dict[str, list[Any]], obj: DetectedObject) -> None:
    """The columns a detection and a ground-truth row share (not frame, stamp, extras)."""
    box = obj.box
    cols["object_id"].append(obj.object_id)
    cols["object_class"].append(obj.object_class.value)
    cx, cy, cz = box.center.tolist()
    sl, sw, sh = box.size.tolist()
    vx, vy, vz = obj.velocity.tolist()
    ax, ay, az = obj.acceleration.tolist()
    for name, value in (
        ("x", cx),
        ("y", cy),
        ("z", cz),
        ("length", sl),
        ("width", sw),
        ("height", sh),
        ("yaw_rad", box.yaw_rad),
        ("vx", vx),
        ("vy", vy),
        ("vz", vz),
        ("ax", ax),
        ("ay", ay),
        ("az", az),
    ):
        cols[name].append(value)
    bbox = obj.bbox_2d
    for j, name in enumerate(("bbox_x", "bbox_y", "bbox_w", "bbox_h")):
        cols[name].append(None if bbox is None else bbox[j])
