"""The ``python -m redrive.live.sources`` command line: one source as its own process."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from types import FrameType

from redrive.errors import RedriveError
from redrive.live.sources._common import _POLL_S
from redrive.live.sources.replay import run_replay_source
from redrive.live.sources.synthetic import run_synthetic_source
from redrive.transport import Policy

logger = logging.getLogger(__name__)


class _SignalStop:
    """A stop flag set from a signal handler (a ``threading.Event`` set there may deadlock), or
    when the process that started this one is gone (a killed ``redrive live`` leaves no orphan
    source publishing into shared memory)."""

    def __init__(self) -> None:
        self._set = False
        self._parent = os.getppid()

    def handle(self, signum: int, frame: FrameType | None) -> None:
        del frame
        logger.info("signal %d: stopping", signum)
        self._set = True

    def is_set(self) -> bool:
        if not self._set and os.getppid() != self._parent:
            logger.warning("the process that started this source is gone: stopping")
            self._set = True
        return self._set

    def wait(self, timeout: float | None = None) -> bool:
        if not self._set:
            time.sleep(_POLL_S if timeout is None else max(0.0, min(timeout, _POLL_S)))
        return self._set


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m redrive.live.sources",
        description="Publish a log or a simulated scenario into shared memory, in real time.",
    )
    sub = parser.add_subparsers(dest="source", required=True)
    replay = sub.add_parser("replay", help="replay a log (bag, MCAP, KITTI)")
    replay.add_argument("log", type=Path)
    replay.add_argument("--topics", nargs="+", default=None, help="only these topics")
    replay.add_argument("--loop", action="store_true", help="play the log again and again")
    synthetic = sub.add_parser("synthetic", help="play a redrive.sim scenario")
    synthetic.add_argument("scenario", help="a catalogue name (urban) or a scenario .toml")
    synthetic.add_argument("--duration", type=float, default=None, help="seconds simulated")
    synthetic.add_argument("--seed", type=int, default=None)
    for p in (replay, synthetic):
        p.add_argument("--session", required=True, help="stream names are <session>.<topic>")
        p.add_argument("--rate", type=float, default=1.0, help="speed; 0 = as fast as possible")
        p.add_argument("--lossless", action="store_true", help="lossless writers (back-pressure)")
        p.add_argument("-v", "--verbose", action="store_true", help="log at INFO")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``python -m redrive.live.sources`` entry: prints ``READY`` once the writers exist."""
    args = _parser().parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING,
        format="%(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    stop = _SignalStop()
    previous = {sig: signal.signal(sig, stop.handle) for sig in (signal.SIGTERM, signal.SIGINT)}

    def ready() -> None:
        print("READY", flush=True)  # the one line a parent process waits for

    rate = None if args.rate == 0 else args.rate
    policy = Policy.LOSSLESS if args.lossless else Policy.KEEP_LATEST
    try:
        if args.source == "replay":
            run_replay_source(
                args.log,
                args.session,
                rate=rate,
                topics=args.topics,
                policy=policy,
                stop=stop,
                loop=args.loop,
                on_ready=ready,
            )
        else:
            run_synthetic_source(
                args.scenario,
                args.session,
                duration_s=args.duration,
                seed=args.seed,
                rate=rate,
                stop=stop,
                policy=policy,
                on_ready=ready,
            )
    except RedriveError as err:
        logger.error("%s", err)
        return 1
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    return 0
