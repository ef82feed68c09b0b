"""``redrive serve``: a WebSocket client sees the channels and the stream's messages in order.

The client speaks the Foxglove WebSocket protocol as foxglove-sdk 0.30 serves it (subprotocol
``foxglove.sdk.v1``): JSON ``serverInfo`` / ``advertise`` / ``subscribe``, binary message data
(opcode 1: subscription id u32, log time u64, payload), time (2), playback state (5) and the
client's playback control request (3).
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import struct
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import websockets

from redrive.interop.serve import Player, serve_stream
from redrive.interop.stream import OutMessage, SceneStream, open_scene_stream

_SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA, _TIME, _PLAYBACK_STATE = 1, 2, 5
_PLAY, _PAUSE = 0, 1
_ENDED = 3


@pytest.fixture
def served(short_run: Path) -> Iterator[tuple[SceneStream, Player, int]]:
    with open_scene_stream(short_run) as stream:
        player, server = serve_stream(stream, port=0, rate=50.0, playing=False)
        thread = threading.Thread(target=player.play, daemon=True)
        thread.start()
        try:
            yield stream, player, server.port
        finally:
            player.stop()
            thread.join(10)
            server.stop()


def _control(command: int, *, speed: float, seek_ns: int | None = None, rid: str) -> bytes:
    head = struct.pack(
        "<BBfBQI", 3, command, speed, seek_ns is not None, seek_ns or 0, len(rid.encode())
    )
    return head + rid.encode()


class _Client:
    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.channels: dict[int, dict[str, Any]] = {}
        self.subscriptions: dict[int, int] = {}
        self.info: dict[str, Any] = {}
        self.received: list[OutMessage] = []
        self.taken = 0
        self.states: list[tuple[int, int, bool, str]] = []
        self.states_taken = 0

    async def next(self) -> str | bytes:
        return await asyncio.wait_for(self.ws.recv(), 30)

    async def handshake(self, expected: int) -> None:
        while len(self.channels) < expected:
            msg = json.loads(await self.next())
            if msg["op"] == "serverInfo":
                self.info = msg
            elif msg["op"] == "advertise":
                self.channels.update({c["id"]: c for c in msg["channels"]})

    async def subscribe_all(self) -> None:
        self.subscriptions = dict(enumerate(self.channels))
        subs = [{"id": i, "channelId": c} for i, c in self.subscriptions.items()]
        await self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    async def _receive(self) -> None:
        """One frame into :attr:`received` (data) or :attr:`states` (playback states); the
        server's time messages are dropped.  Data and control frames travel on separate queues
        of the server, so a state may overtake data sent before it."""
        frame = await self.next()
        if isinstance(frame, bytes) and frame[0] == _MESSAGE_DATA:
            sub, log_time = struct.unpack_from("<IQ", frame, 1)
            topic = self.channels[self.subscriptions[sub]]["topic"]
            self.received.append(OutMessage(topic, log_time, bytes(frame[13:])))
        elif isinstance(frame, bytes) and frame[0] == _PLAYBACK_STATE:
            st, current, _speed, did_seek, n = struct.unpack_from("<BQfBI", frame, 1)
            self.states.append((st, current, bool(did_seek), frame[19 : 19 + n].decode()))

    async def data(self, n: int) -> list[OutMessage]:
        """The next ``n`` data messages."""
        start = self.taken
        while len(self.received) < start + n:
            await self._receive()
        self.taken = start + n
        return self.received[start : start + n]

    async def state(self, status: int | None = None) -> tuple[int, int, bool, str]:
        """The next playback state not yet taken (``status``: the next with that status)."""
        while True:
            while self.states_taken >= len(self.states):
                await self._receive()
            found = self.states[self.states_taken]
            self.states_taken += 1
            if status is None or found[0] == status:
                return found


def test_a_client_sees_the_channels_and_the_first_messages_in_order(
    served: tuple[SceneStream, Player, int],
) -> None:
    stream, _, port = served
    expected = list(itertools.islice(stream.messages(), 60))

    async def session() -> tuple[_Client, list[OutMessage]]:
        url = f"ws://127.0.0.1:{port}"
        async with websockets.connect(
            url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
        ) as ws:  # the SDK server does not answer the close handshake: do not wait 10 s
            client = _Client(ws)
            await client.handshake(len(stream.channels))
            await client.subscribe_all()
            await ws.send(_control(_PLAY, speed=50.0, rid="go"))
            return client, await client.data(60)

    client, got = asyncio.run(session())
    assert set(client.info["capabilities"]) >= {"playbackControl", "time"}
    start = client.info["dataStartTime"]
    assert start["sec"] * 10**9 + start["nsec"] == expected[0].log_time_ns
    by_topic = {c["topic"]: c for c in client.channels.values()}
    assert set(by_topic) == set(stream.channels)
    for topic, schema, encoding in (
        ("/lidar_top", "sensor_msgs/msg/PointCloud2", "cdr"),
        ("/redrive/ground_truth", "foxglove.SceneUpdate", "protobuf"),
        ("/redrive/transforms", "foxglove.FrameTransforms", "protobuf"),
        ("/foxglove/lidar_top", "foxglove.PointCloud", "protobuf"),
        ("/redrive/markers/ground_truth", "visualization_msgs/msg/MarkerArray", "cdr"),
    ):
        channel = by_topic[topic]
        assert (channel["schemaName"], channel["encoding"]) == (schema, encoding)
        spec = stream.channels[topic]
        text = channel["schema"]
        sent = base64.b64decode(text) if spec.schema_encoding == "protobuf" else text.encode()
        assert sent == spec.schema_data
    assert got == expected


def test_the_app_seeks_and_the_stream_restarts_there(
    served: tuple[SceneStream, Player, int],
) -> None:
    stream, player, port = served
    total = sum(1 for _ in stream.messages())
    frames = stream.run.table("frames").column("stamp_ns").to_pylist() if stream.run else []
    seek_ns = int(frames[5])
    after_seek = list(itertools.islice(stream.messages(start_ns=seek_ns), 10))

    async def session() -> tuple[list[OutMessage], tuple[int, int, bool, str]]:
        url = f"ws://127.0.0.1:{port}"
        async with websockets.connect(
            url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
        ) as ws:  # the SDK server does not answer the close handshake: do not wait 10 s
            client = _Client(ws)
            await client.handshake(len(stream.channels))
            await client.subscribe_all()
            await ws.send(_control(_PLAY, speed=50.0, rid="go"))
            await client.data(total)  # everything, then the player says it ended
            await client.state(_ENDED)
            await ws.send(_control(_PLAY, speed=50.0, seek_ns=seek_ns, rid="seek"))
            answer = await client.state()
            return await client.data(10), answer

    got, (status, current, did_seek, rid) = asyncio.run(session())
    assert (status, current, did_seek, rid) == (0, seek_ns, True, "seek")  # 0: playing
    assert got == after_seek
    assert player.sent >= total + 10


def test_the_old_subprotocol_alone_is_refused_and_offered_beside_the_new_one_is_served(
    served: tuple[SceneStream, Player, int],
) -> None:
    # issue 35 item 12, as docs/foxglove.md says: foxglove-sdk's server speaks only
    # `foxglove.sdk.v1` (the same protocol as `foxglove.websocket.v1` under a new name); a client
    # that offers only the old name gets HTTP 400, one that offers both is served
    _, _, port = served
    url = f"ws://127.0.0.1:{port}"

    async def old_only() -> int | None:
        try:
            async with websockets.connect(url, subprotocols=["foxglove.websocket.v1"]):
                return None
        except websockets.exceptions.InvalidStatus as err:
            return err.response.status_code

    async def both() -> str | None:
        async with websockets.connect(
            url, subprotocols=["foxglove.websocket.v1", _SUBPROTOCOL], close_timeout=1
        ) as ws:
            info = json.loads(await asyncio.wait_for(ws.recv(), 10))
            assert info["op"] == "serverInfo"
            return ws.subprotocol

    assert asyncio.run(old_only()) == 400
    assert asyncio.run(both()) == _SUBPROTOCOL


def test_a_real_bag_run_is_paced_on_the_log_time_axis(luminar_run: Path) -> None:
    # issue 35 item 6: the Luminar bag's frames are stamped 237.8 days before their log times;
    # served at their stamps, the results came first and the player then waited 237.8 days for
    # the clouds.  Now the results sit at their clouds' log times: the whole stream (7.6 s of
    # log) plays in its log span ÷ rate, clouds and their results side by side.
    rate = 4.0
    with open_scene_stream(luminar_run) as stream:
        assert stream.reader is not None
        assert (stream.start_ns, stream.end_ns) == (stream.reader.start_ns, stream.reader.end_ns)
        expected = list(stream.messages())
        player, server = serve_stream(stream, port=0, rate=rate, playing=False)
        thread = threading.Thread(target=player.play, daemon=True)
        thread.start()
        try:

            async def session() -> tuple[list[OutMessage], float]:
                url = f"ws://127.0.0.1:{server.port}"
                async with websockets.connect(
                    url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
                ) as ws:
                    client = _Client(ws)
                    await client.handshake(len(stream.channels))
                    await client.subscribe_all()
                    await ws.send(_control(_PLAY, speed=rate, rid="go"))
                    first = await client.data(1)
                    started = time.monotonic()
                    rest = await client.data(len(expected) - 1)
                    return first + rest, time.monotonic() - started

            got, elapsed_s = asyncio.run(session())
        finally:
            player.stop()
            thread.join(10)
            server.stop()
    assert got == expected
    span_s = (expected[-1].log_time_ns - expected[0].log_time_ns) / 1e9
    assert span_s < 8.0  # one axis: nothing 237.8 days away
    assert elapsed_s >= 0.9 * span_s / rate  # paced, not sent at once
    clouds = [m.log_time_ns for m in got if m.topic == "/luminar_pointcloud"]
    boxes = [m.log_time_ns for m in got if m.topic == "/redrive/detections/cluster-detector"]
    assert len(clouds) == len(boxes) == 5
    assert clouds == boxes  # each frame's results at its cloud's log time


def test_a_client_that_subscribes_later_gets_the_map_sent_before(
    served: tuple[SceneStream, Player, int],
) -> None:
    """/redrive/map goes out once, with the first frame (h-mapfile's limit: a client joining
    later never saw it): a second client subscribing after the whole run was played, with the
    player paused at its end, gets that same map message."""
    from redrive.interop.map_shapes import MAP_TOPIC

    stream, player, port = served
    total = sum(1 for _ in stream.messages())
    assert MAP_TOPIC in stream.channels
    first_map = next(m for m in stream.messages() if m.topic == MAP_TOPIC)
    url = f"ws://127.0.0.1:{port}"

    async def session() -> list[OutMessage]:
        async with websockets.connect(
            url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
        ) as ws:
            client = _Client(ws)
            await client.handshake(len(stream.channels))
            await client.subscribe_all()
            await ws.send(_control(_PLAY, speed=50.0, rid="go"))
            sent = await client.data(total)
            await client.state(_ENDED)
            assert sum(m.topic == MAP_TOPIC for m in sent) == 1
            async with websockets.connect(
                url, subprotocols=[_SUBPROTOCOL], max_size=None, close_timeout=1
            ) as ws2:
                late = _Client(ws2)
                await late.handshake(len(stream.channels))
                await late.subscribe_all()
                return await late.data(1)

    (got,) = asyncio.run(session())
    assert got == first_map
    assert player.sent == total  # the resend is not a played message
