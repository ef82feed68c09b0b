"""The Foxglove live view's results: a frame the engine finished reaches a WebSocket client as
scene updates — boxes where the detector put them, the planned path, the ego and its transform.

The client speaks the protocol as tests/interop/test_serve.py does (subprotocol
``foxglove.sdk.v1``); the protobuf messages are decoded with the schemas the server sent.
"""

from __future__ import annotations

import asyncio
import base64
import json
import struct
import time
from collections import defaultdict
from typing import Any

import numpy as np
import websockets
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from redrive.interop.live_view import LiveView
from redrive.results.records import FrameRecord, StepRecord
from redrive.types import Box3D, DetectedObject, ObjectClass, PlannedPath, VehicleState

_SUBPROTOCOL = "foxglove.sdk.v1"
_STAMP = 1_700_000_000_123_000_000
_DETECTIONS, _PATH = "/redrive/detections/det", "/redrive/paths/planner"
_EGO, _GT, _TF = "/redrive/ego", "/redrive/ground_truth", "/redrive/transforms"


def _object(oid: int, x: float, y: float) -> DetectedObject:
    return DetectedObject(
        object_id=oid,
        object_class=ObjectClass.VEHICLE,
        confidence=0.8,
        box=Box3D(center=np.array([x, y, 0.8]), size=np.array([4.5, 1.9, 1.6]), yaw_rad=0.3),
        velocity=np.array([2.0, 0.0, 0.0]),
    )


def _record() -> FrameRecord:
    path = PlannedPath(
        stamp_ns=_STAMP,
        frame_id="map",
        waypoints=np.array([[10.0, 5.0, 0.0, 0.0], [12.0, 6.0, 0.0, 0.5], [14.0, 7.5, 0.0, 1.0]]),
    )
    return FrameRecord(
        frame_index=7,
        stamp_ns=_STAMP,
        steps=(
            StepRecord(
                algorithm="det",
                stage="perception",
                role="perception",
                status="ok",
                output=(_object(3, 12.0, -2.0), _object(4, 20.0, 3.5)),
            ),
            StepRecord(
                algorithm="planner", stage="planning", role="planning", status="ok", output=path
            ),
        ),
        vehicle_state=VehicleState(
            stamp_ns=_STAMP, frame_id="map", position=np.array([10.0, 5.0, 0.0]), heading_rad=0.5
        ),
        ground_truth=(_object(1, 12.1, -2.1),),
    )


def _proto_class(channel: dict[str, Any]) -> Any:
    files = descriptor_pb2.FileDescriptorSet.FromString(base64.b64decode(channel["schema"]))
    pool = descriptor_pool.DescriptorPool()
    for file in files.file:
        pool.Add(file)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(channel["schemaName"]))


def test_a_finished_frame_reaches_a_client_as_scene_updates() -> None:
    view = LiveView(port=0)
    record = _record()
    try:
        view.add_results([("det", "perception"), ("planner", "planning")])

        async def watch() -> tuple[dict[str, dict[str, Any]], dict[str, list[tuple[int, bytes]]]]:
            url = f"ws://127.0.0.1:{view.port}"
            async with websockets.connect(
                url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
            ) as ws:
                channels: dict[int, dict[str, Any]] = {}
                got: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
                wanted = {_DETECTIONS, _PATH, _EGO, _GT, _TF}
                deadline = time.monotonic() + 30
                while not wanted <= {c["topic"] for c in channels.values()}:
                    msg = json.loads(await asyncio.wait_for(ws.recv(), 30))
                    if msg["op"] == "advertise":
                        channels.update({c["id"]: c for c in msg["channels"]})
                subs = dict(enumerate(channels))
                request = [{"id": s, "channelId": c} for s, c in subs.items()]
                await ws.send(json.dumps({"op": "subscribe", "subscriptions": request}))
                # the server takes the subscription in its own time: hand the frame over again
                # until its results arrive (each hand-over replaces the one still waiting)
                while not wanted <= set(got):
                    assert time.monotonic() < deadline, f"only {sorted(got)} arrived"
                    view.on_frame(record)
                    try:
                        frame = await asyncio.wait_for(ws.recv(), 0.2)
                    except TimeoutError:
                        continue
                    if isinstance(frame, bytes) and frame[0] == 1:
                        sub, log_time = struct.unpack_from("<IQ", frame, 1)
                        got[channels[subs[sub]]["topic"]].append((log_time, bytes(frame[13:])))
                return {c["topic"]: c for c in channels.values()}, got

        channels, got = asyncio.run(watch())
    finally:
        view.close()

    assert {c["schemaName"] for t, c in channels.items() if t.startswith("/redrive/markers/")} == {
        "visualization_msgs/msg/MarkerArray"
    }
    assert {log_time for messages in got.values() for log_time, _ in messages} == {_STAMP}

    def decoded(topic: str) -> Any:
        return _proto_class(channels[topic]).FromString(got[topic][0][1])

    boxes = {e.id: e for e in decoded(_DETECTIONS).entities if e.cubes}
    assert set(boxes) == {"det/3", "det/4"}
    for entity, obj in zip(
        (boxes["det/3"], boxes["det/4"]), record.steps[0].output or (), strict=True
    ):
        assert isinstance(obj, DetectedObject)
        cube = entity.cubes[0]
        assert entity.frame_id == "base_link"
        assert (cube.pose.position.x, cube.pose.position.y, cube.pose.position.z) == tuple(
            obj.box.center
        )
        assert (cube.size.x, cube.size.y, cube.size.z) == tuple(obj.box.size)
        assert entity.arrows  # it moves: its velocity is drawn
    (line,) = [e for e in decoded(_PATH).entities if e.lines]
    assert line.frame_id == "map"
    assert [(p.x, p.y, p.z) for p in line.lines[0].points] == [
        (10.0, 5.0, 0.0),
        (12.0, 6.0, 0.0),
        (14.0, 7.5, 0.0),
    ]
    (ego,) = [e for e in decoded(_EGO).entities if e.cubes]
    assert ego.frame_id == "map"
    assert [e.id for e in decoded(_GT).entities if e.cubes] == ["gt/1"]
    (transform,) = decoded(_TF).transforms
    assert (transform.parent_frame_id, transform.child_frame_id) == ("map", "base_link")
    assert (transform.translation.x, transform.translation.y) == (10.0, 5.0)
    assert view.frames_shown >= 1
