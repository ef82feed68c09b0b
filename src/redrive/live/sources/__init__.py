"""Sources for live mode: a log replayed, or the simulator played, in real time into shared memory.

Each topic goes through its own :class:`~redrive.transport.Writer` (stream
``<session>.<topic>``, see :mod:`redrive.live.streams`) as typed
:class:`~redrive.types.SensorData` samples — a stand-in for a sensor rig:

* :func:`run_replay_source` publishes a log's messages at their recorded rate (log time scaled
  by ``rate``); :func:`replay_streams` says which streams that makes.
* :func:`run_synthetic_source` steps the :mod:`redrive.sim` world in real time and publishes
  each sensor sample when it is due; :func:`synthetic_streams` says which streams that makes.

Both create every writer first (``on_ready`` is called then), publish, and close (unlink) their
writers on every way out.  Samples are prepared (decoded, rendered) ahead and published at their
due time; one published more than 10 ms after it was due is counted as *late*, never dropped.
``stop`` (a ``threading.Event`` or a ``multiprocessing`` event) ends a source within ~50 ms of
the sample being prepared.

Run one as its own process (it prints ``READY`` once its writers exist, and stops cleanly —
segments unlinked — on SIGTERM or SIGINT)::

    python -m redrive.live.sources replay drive.mcap --session live-1 --rate 1.0
    python -m redrive.live.sources synthetic urban --session live-1
"""

from __future__ import annotations

from redrive.live.sources._cli import main
from redrive.live.sources._common import DEFAULT_MAX_READERS as DEFAULT_MAX_READERS
from redrive.live.sources._common import DEFAULT_SLOTS as DEFAULT_SLOTS
from redrive.live.sources._common import LATE_AFTER_NS as LATE_AFTER_NS
from redrive.live.sources._common import Location as Location
from redrive.live.sources._common import StopEvent
from redrive.live.sources.replay import CAPACITY_HEADROOM as CAPACITY_HEADROOM
from redrive.live.sources.replay import LOOP_GAP_NS as LOOP_GAP_NS
from redrive.live.sources.replay import ReplayStats, replay_streams, run_replay_source
from redrive.live.sources.synthetic import SyntheticStats, run_synthetic_source, synthetic_streams

__all__ = [
    "ReplayStats",
    "StopEvent",
    "SyntheticStats",
    "main",
    "replay_streams",
    "run_replay_source",
    "run_synthetic_source",
    "synthetic_streams",
]
