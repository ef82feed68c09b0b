"""``redrive serve RUN|LOG``: the scene stream live on Foxglove's WebSocket protocol.

The :class:`~redrive.interop.stream.SceneStream` of a run or a log is advertised on a
``foxglove-sdk`` WebSocket server (loopback unless told otherwise) and played at ``rate`` × its
log time.  The server announces the log's time range, so the Foxglove app shows its own player:
play, pause, speed and seek (the SDK's ``PlaybackControl`` capability) act on this
:class:`Player`, which answers each request with its new playback state and broadcasts the time
of every message it sends.

Playing starts when ``play`` is given, or on the app's first Play; the player waits for a client
before it starts, so the first messages reach someone.  At the end it stays, paused at the last
message, until the app seeks or the server is stopped.

The road map (``/redrive/map``) is sent once, with the first frame, as a latched ROS topic is:
the player keeps the last message of each :data:`LATCHED_TOPICS` topic and sends it again when a
client subscribes to that topic later (a second app window, a reconnect), playing or paused.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import foxglove
from foxglove.websocket import (
    Capability,
    ChannelView,
    Client,
    PlaybackCommand,
    PlaybackControlRequest,
    PlaybackState,
    PlaybackStatus,
    WebSocketServer,
)

from redrive.errors import ConfigError
from redrive.interop.map_shapes import MAP_TOPIC
from redrive.interop.serve_defaults import DEFAULT_HOST, DEFAULT_PORT
from redrive.interop.stream import OutMessage, SceneStream

__all__ = ["LATCHED_TOPICS", "Player", "serve_stream"]

#: topics sent once that a client subscribing later gets again (the map does not change)
LATCHED_TOPICS = frozenset({MAP_TOPIC})

logger = logging.getLogger(__name__)

#: longest sleep between checks of a pause, seek or stop request, seconds.
_POLL_S = 0.05


class Player:
    """Plays a stream's messages onto its channels at ``rate`` × log time, under the app's
    control.  Thread-safe: the server's callbacks change the state the playing thread reads."""

    def __init__(
        self,
        stream: SceneStream,
        *,
        context: foxglove.Context,
        rate: float = 1.0,
        playing: bool = False,
    ) -> None:
        if not rate > 0:
            msg = f"the playback rate must be > 0, got {rate}"
            raise ConfigError(msg)
        self.stream = stream
        # the server only advertises channels while their context lives: the player keeps it
        self.context = context
        self.rate = rate
        self.start_ns = stream.start_ns
        self.end_ns = max(stream.end_ns, self.start_ns)
        self.sent = 0
        self.server: WebSocketServer | None = None
        self._cond = threading.Condition()
        self._playing = playing
        self._seek_ns: int | None = None
        self._stop = False
        self._subscriptions = 0
        self._time_ns = self.start_ns
        self._ended = False
        self._latched: dict[str, OutMessage] = {}  # topic → its last message sent
        self._resend: list[str] = []  # latched topics a client subscribed to since
        self._channels = {
            topic: foxglove.Channel(
                topic,
                schema=foxglove.Schema(
                    name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data
                ),
                message_encoding=spec.message_encoding,
                context=context,
                metadata=dict(spec.metadata),
            )
            for topic, spec in stream.channels.items()
        }

    # -- the server's callbacks (ServerListener) ---------------------------------------------------

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self._cond:
            self._subscriptions += 1
            if channel.topic in self._latched:  # sent by the playing thread, not the server's
                self._resend.append(channel.topic)
            self._cond.notify_all()

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        with self._cond:
            self._subscriptions = max(0, self._subscriptions - 1)

    def on_playback_control_request(self, request: PlaybackControlRequest) -> PlaybackState:
        with self._cond:
            if request.playback_speed > 0:
                self.rate = float(request.playback_speed)
            if request.seek_time is not None:
                self._seek_ns = min(max(int(request.seek_time), self.start_ns), self.end_ns)
                self._time_ns = self._seek_ns
                self._ended = False
            self._playing = request.playback_command == PlaybackCommand.Play and not self._ended
            self._cond.notify_all()
            return self._state(
                did_seek=request.seek_time is not None, request_id=request.request_id
            )

    def _state(self, *, did_seek: bool = False, request_id: str | None = None) -> PlaybackState:
        if self._ended:
            status = PlaybackStatus.Ended
        else:
            status = PlaybackStatus.Playing if self._playing else PlaybackStatus.Paused
        return PlaybackState(
            status=status,
            current_time=self._time_ns,
            playback_speed=self.rate,
            did_seek=did_seek,
            request_id=request_id,
        )

    # -- playing ---------------------------------------------------------------------------------

    def stop(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()

    def _wait_to_play(self) -> bool:
        """Block while paused or without a client (sending latched messages asked for);
        False when stopped."""
        while True:
            self._send_latched()
            with self._cond:
                if self._stop:
                    return False
                if self._playing and self._subscriptions > 0 and not self._resend:
                    return True
                if not self._resend:
                    self._cond.wait(_POLL_S * 4)

    def _send_latched(self) -> None:
        """Send again the latched messages that clients subscribed to since (outside the lock:
        the server's callbacks take it)."""
        if not self._resend:  # the common case, every message: no lock taken
            return
        with self._cond:
            topics, self._resend = self._resend, []
            again = [self._latched[t] for t in dict.fromkeys(topics) if t in self._latched]
        for message in again:
            self._channels[message.topic].log(message.data, log_time=message.log_time_ns)

    def _take_seek(self) -> int | None:
        with self._cond:
            seek, self._seek_ns = self._seek_ns, None
            return seek

    def play(self, *, on_message: Callable[[OutMessage], None] | None = None) -> int:
        """Play until :meth:`stop` (from another thread); returns the messages sent."""
        messages: Iterator[OutMessage] = self.stream.messages()
        anchor: tuple[float, int] | None = None  # (wall s, log ns) of the pacing origin
        while self._wait_to_play():
            seek = self._take_seek()
            if seek is not None:
                messages, anchor = self.stream.messages(start_ns=seek), None
            message = next(messages, None)
            if message is None:
                self._finish()
                continue
            with self._cond:
                rate = self.rate
            if anchor is None or anchor[1] > message.log_time_ns:
                anchor = (time.monotonic(), message.log_time_ns)
            due = anchor[0] + (message.log_time_ns - anchor[1]) / 1e9 / rate
            if not self._sleep_until(due):
                anchor = None  # paused, sought or rate changed: restart the clock here
                messages = _prepend(message, messages)
                continue
            self._channels[message.topic].log(message.data, log_time=message.log_time_ns)
            self.sent += 1
            with self._cond:
                self._time_ns = message.log_time_ns
                if message.topic in LATCHED_TOPICS:
                    self._latched[message.topic] = message
            if self.server is not None:
                self.server.broadcast_time(message.log_time_ns)
            if on_message is not None:
                on_message(message)
        return self.sent

    def _sleep_until(self, due_s: float) -> bool:
        """Sleep until ``due_s`` (monotonic); False when a pause, seek, rate change or stop came
        first."""
        with self._cond:
            rate = self.rate
        while True:
            self._send_latched()
            left = due_s - time.monotonic()
            with self._cond:
                if (
                    self._stop
                    or not self._playing
                    or self._seek_ns is not None
                    or self.rate != rate
                ):
                    return False
                if left <= 0:
                    return True
                self._cond.wait(min(left, _POLL_S))

    def _finish(self) -> None:
        with self._cond:
            self._playing = False
            self._ended = True
            state = self._state()
        if self.server is not None:
            self.server.broadcast_playback_state(state)
        logger.info("played to the end: %d messages", self.sent)


def _prepend(first: OutMessage, rest: Iterator[OutMessage]) -> Iterator[OutMessage]:
    yield first
    yield from rest


def serve_stream(
    stream: SceneStream,
    *,
    host: str = DEFAULT_HOST,
    port: int = DEFAULT_PORT,
    rate: float = 1.0,
    playing: bool = True,
    name: str = "redrive",
) -> tuple[Player, WebSocketServer]:
    """Start a WebSocket server for ``stream`` and its :class:`Player` (not yet playing: call
    ``player.play()``, which blocks, and ``player.stop()`` then ``server.stop()`` to end).

    Raises:
        ConfigError: the port cannot be bound (the message says which and what to do).
    """
    context = foxglove.Context()
    player = Player(stream, context=context, rate=rate, playing=playing)
    listener: Any = player
    try:
        server = foxglove.start_server(
            name=name,
            host=host,
            port=port,
            capabilities=[Capability.Time, Capability.PlaybackControl],
            server_listener=listener,
            context=context,
            playback_time_range=(player.start_ns, player.end_ns),
        )
    except RuntimeError as err:
        msg = (
            f"cannot serve on {host}:{port} ({err}); another program may use the port: "
            "choose another with --port (0 picks a free one)"
        )
        raise ConfigError(msg) from err
    player.server = server
    return player, server
