"""``redrive live … --foxglove``: the session's streams and results to a Foxglove live view.

The glue between :mod:`redrive.live` (the session's shared-memory streams, read as a log by
:class:`~redrive.live.dispatcher.LiveLog`) and :mod:`redrive.interop` (the WebSocket server and
the Foxglove conversions), which do not import each other.  The view reads every stream as one
more *keep-latest* reader in threads of its own, so neither the sources, the recorder nor the
pipeline ever wait for it: what it misses while it is busy it does not show.
"""

from __future__ import annotations

import argparse
import threading
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from redrive.config import PipelineConfig
    from redrive.live.dispatcher import LiveLog
    from redrive.live.streams import StreamSpec
    from redrive.results.records import FrameRecord

__all__ = ["FoxgloveFeed", "add_arguments", "both", "open_feed"]


class FoxgloveFeed:
    """A :class:`~redrive.interop.live_view.LiveView` fed by a live session (see the module
    text).  :meth:`follow` the session's streams (again when topics were added), hand
    :meth:`on_frame` to the engine, :meth:`close` at the end."""

    def __init__(self, *, host: str, port: int, session: str) -> None:
        from redrive.interop import require_foxglove

        require_foxglove()
        from redrive.interop.live_view import LiveView

        self.view = LiveView(host=host, port=port)
        self.session = session
        self._stop = threading.Event()
        self._followed: set[str] = set()
        self._logs: list[LiveLog] = []
        self._threads: list[threading.Thread] = []

    def follow(self, specs: Sequence[StreamSpec]) -> None:
        """Show the streams of ``specs`` not shown yet (each read by one more reader)."""
        from redrive.live.dispatcher import LiveLog

        new = [s for s in specs if s.topic not in self._followed]
        if not new:
            return
        log = LiveLog(new, self.session, stop=self._stop, warn_gone=False)
        self._followed.update(s.topic for s in new)
        self._logs.append(log)
        self.view.add_topics(log.topics.values(), log.typestores)
        thread = threading.Thread(
            target=self.view.feed,
            args=(log.messages(), log.deserialize),
            name="redrive-foxglove-feed",
            daemon=True,
        )
        self._threads.append(thread)
        thread.start()

    def add_results(self, pipeline: PipelineConfig) -> None:
        """Advertise the results channels of ``pipeline``'s algorithms whose role is known."""
        self.view.add_results(
            (algorithm.name, stage.role)
            for stage in pipeline.stages
            if stage.role is not None
            for algorithm in stage.algorithms
        )

    def on_frame(self, record: FrameRecord) -> None:
        self.view.on_frame(record)

    def close(self) -> None:
        self._stop.set()
        for thread in self._threads:
            thread.join(5.0)
        for log in self._logs:
            log.close()
        self.view.close()

    def summary(self) -> str:
        view = self.view
        sent = sum(view.sent.values())
        text = (
            f"foxglove: {sent} messages sent on {sum(1 for n in view.sent.values() if n)} of "
            f"{len(view.sent)} channels"
        )
        if view.frames_shown or view.frames_skipped:
            text += (
                f"; results of {view.frames_shown} frames shown, {view.frames_skipped} passed over "
                "(the view was behind)"
            )
        if view.unconvertible:
            text += f"; {view.unconvertible} messages could not be converted"
        return text


def open_feed(
    args: argparse.Namespace,
    session: str,
    specs: Sequence[StreamSpec],
    *,
    pipeline: PipelineConfig | None = None,
) -> FoxgloveFeed | None:
    """A feed of ``specs`` (and of ``pipeline``'s results) when ``--foxglove`` was given, else
    None.  Its URL is printed on stdout once the channels exist: a client that connects then
    finds them all."""
    if not args.foxglove:
        return None
    feed = FoxgloveFeed(host=args.foxglove_host, port=args.foxglove_port, session=session)
    try:
        feed.follow(specs)
        if pipeline is not None:
            feed.add_results(pipeline)
    except BaseException:
        feed.close()
        raise
    print(f"foxglove: live view on {feed.view.url} (open it in Foxglove)", flush=True)
    return feed


def both(
    first: Callable[[FrameRecord], None] | None, second: Callable[[FrameRecord], None] | None
) -> Callable[[FrameRecord], None] | None:
    """One ``on_frame`` calling ``first`` then ``second`` (either may be None)."""
    if first is None or second is None:
        return first or second

    def call(record: FrameRecord) -> None:
        first(record)
        second(record)

    return call


def add_arguments(parser: Any) -> None:
    """``--foxglove``, ``--foxglove-host``, ``--foxglove-port`` of ``redrive live``."""
    from redrive.interop.serve_defaults import DEFAULT_HOST, DEFAULT_PORT

    parser.add_argument(
        "--foxglove",
        action="store_true",
        help="also stream the session live to Foxglove (WebSocket; the topics as they arrive "
        "and each frame's results; needs `pip install 'redrive[foxglove]'`)",
    )
    parser.add_argument(
        "--foxglove-host",
        default=DEFAULT_HOST,
        metavar="HOST",
        help=f"--foxglove: address to listen on (default {DEFAULT_HOST}; 0.0.0.0 opens it to "
        "the network)",
    )
    parser.add_argument(
        "--foxglove-port",
        type=int,
        default=DEFAULT_PORT,
        metavar="PORT",
        help=f"--foxglove: TCP port (default {DEFAULT_PORT}; 0 picks a free one)",
    )
