"""``redrive serve RUN|LOG`` — a run over its log, or a log, live in Foxglove (WebSocket)."""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import Any

__all__ = ["register"]

_EPILOG = """\
examples:
  redrive serve runs/urban                 the run over its log at 1x on ws://127.0.0.1:8765
  redrive serve urban.mcap --rate 2        a log at twice its speed
  redrive serve runs/urban --port 9000 --paused   wait for Play in the app

Open Foxglove → Open connection → Foxglove WebSocket → ws://127.0.0.1:8765 (the URL printed),
then Layout → Import from file → docs/foxglove_layout.json.  The app's player controls the
stream: play, pause, speed and seek.  Playing starts when the first panel subscribes (or on Play
with --paused); at the end the stream pauses on its last message.  Ctrl-C (or SIGTERM) stops
the server.
The channels are those of `redrive export RUN --format mcap` (docs/foxglove.md).  Needs
`pip install 'redrive[foxglove]'`.
"""


def _run(args: argparse.Namespace) -> int:
    from redrive.interop import require_foxglove

    require_foxglove()
    from redrive.interop.serve import serve_stream
    from redrive.interop.stream import open_scene_stream

    overrides = None
    if args.sensor_map is not None:
        from redrive.assembly.sensor_map import load_sensor_map_overrides

        overrides = load_sensor_map_overrides(args.sensor_map)
    with open_scene_stream(args.path, sensor_map=overrides) as stream:
        player, server = serve_stream(
            stream, host=args.host, port=args.port, rate=args.rate, playing=not args.paused
        )
        url = f"ws://{args.host}:{server.port}"
        print(f"serving {args.path} on {url} ({len(stream.channels)} channels); Ctrl-C stops")
        sys.stdout.flush()
        stop = threading.Event()
        previous = signal.signal(signal.SIGTERM, lambda *_: stop.set())
        playing = threading.Thread(target=player.play, name="redrive-serve", daemon=True)
        playing.start()
        try:
            while playing.is_alive() and not stop.is_set():
                playing.join(0.5)
        except KeyboardInterrupt:
            pass
        finally:
            signal.signal(signal.SIGTERM, previous)
            player.stop()
            playing.join(5.0)
            server.stop()
    print(f"stopped after {player.sent} messages")
    return 0


def register(sub: Any) -> None:
    from redrive.interop.serve_defaults import DEFAULT_HOST, DEFAULT_PORT

    parser = sub.add_parser(
        "serve",
        help="stream a run or a log live to Foxglove (WebSocket, with the app's playback controls)",
        description=(
            "Start foxglove-sdk's WebSocket server and stream a log — or a run over its log, with "
            "its ground truth, detections, tracks, paths, ego and bookmarks as Foxglove scene "
            "updates — at its own pace (--rate times it). The Foxglove app plays, pauses, seeks "
            "and changes the speed. Listens on the loopback interface unless --host says "
            "otherwise."
        ),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("path", type=Path, help="a run directory (the --out of a run) or a log")
    parser.add_argument(
        "--host",
        default=DEFAULT_HOST,
        help=f"address to listen on (default {DEFAULT_HOST}; 0.0.0.0 opens it to the network)",
    )
    parser.add_argument(
        "--port",
        type=int,
        default=DEFAULT_PORT,
        help=f"TCP port (default {DEFAULT_PORT}, Foxglove's; 0 picks a free one)",
    )
    parser.add_argument(
        "--rate",
        type=float,
        default=1.0,
        help="playback speed, times real time (default 1; the app can change it)",
    )
    parser.add_argument(
        "--paused",
        action="store_true",
        help="start paused: nothing is sent until Play is pressed in the app",
    )
    parser.add_argument(
        "--sensor-map",
        type=Path,
        metavar="TOML",
        help="a run: the sensor map file it was given (as `redrive export --sensor-map`)",
    )
    parser.set_defaults(func=_run)
