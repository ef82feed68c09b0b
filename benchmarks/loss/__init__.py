"""``python -m benchmarks loss``: the paper's loss experiment, legacy pipes + pickle against redrive.

Four sensor streams are produced by a *collector* process, paced by the wall clock, and handed to
a *core* process (sizes: bytes of sensor data, plus a 16-byte header and an 8-byte trailer):

=============  =========  ============================================================  ==========
stream         rate (1×)  data                                                          bytes
=============  =========  ============================================================  ==========
``lidar3d``    60 Hz      a VLP-16 sweep: 16 rings × 1800 azimuths = 28,800 points of   633,600
                          x, y, z, intensity f32 + ring u16 + time f32 (22 B, packed)
``lidar2d``    15 Hz      1081 ranges f32 (270° at 0.25°), padded to 8 bytes            4,328
``camera``     15 Hz      1280 × 720 rgb8                                               2,764,800
``imu``        15 Hz      10 f64 (orientation xyzw, angular velocity, acceleration)     80
=============  =========  ============================================================  ==========

and again at ``rate_factor`` times those rates (10×: 600 / 150 / 150 / 150 Hz, ≈ 800 MB/s).

Chains (each a fresh set of processes started with ``multiprocessing`` ``spawn``):

- ``legacy`` — the paper's first design: collector → ``multiprocessing.Pipe`` (``send``: pickle)
  → *bridge* (the paper's ROS handler: unpickles, wraps the payload in a ROS-message-like dict
  ``{"topic", "header": {"seq", "stamp_ns", "frame_id"}, "data"}``) → ``multiprocessing.Queue``
  (``maxsize`` :data:`QUEUE_DEPTH`; pickled again by its feeder thread) → core (``get``). One pipe
  and one queue carry all four streams, as one collector and one handler did. The payload is one
  contiguous numpy array, the cheapest thing pickle can carry: a favourable baseline.
- ``redrive`` — one :class:`redrive.transport.Writer` per stream, ``KEEP_LATEST`` (the sensor
  policy), :data:`SLOTS` slots (redrive.live's default); the collector fills the slot in place
  (``loan``); the core has one thread per stream reading with ``Reader.view`` (no copy).
- ``redrive-lossless`` — the same with ``Policy.LOSSLESS`` (the writer waits for the core).

What every process does, the same in every chain:

- **sensor clock**: message ``k`` (IDs 1, 2, … per stream) of a stream at rate ``f`` is *due* at
  ``t0 + (k − 1) / f`` on ``CLOCK_MONOTONIC`` (``time.monotonic_ns``, one clock for all
  processes); the run produces the IDs due before ``t0 + seconds``.
- **collector** (one thread): sleeps until the earliest due message of any stream, copies the
  stream's fixed template into the outgoing buffer (the legacy chain: a preallocated array, then
  ``send``; redrive: the loaned slot), writes the ID and the hand-over time into the header and
  the ID into the trailer. A sensor does not wait for its collector: if the collector falls
  :data:`SENSOR_BUFFER_S` of messages behind a stream (blocked in the transport, or starved of
  CPU), the oldest are overwritten and never sent (*skipped at the collector*), as in a driver's
  ring buffer; short of that, late messages are sent late, in order, also after ``t0 + seconds``
  for up to :data:`DRAIN_S` / 2 (what is left then is *unsent at the end*). Before ``t0`` it
  sends one warm-up message (ID 0, ignored by the core) per stream through the chain.
- **core** ("light work"): reads the ID from the header and from the trailer (they must agree, or
  the message counts as corrupt) and sums one byte per 4 KiB page of the payload, so every page
  is touched; the receipt time is ``monotonic_ns`` when the transport handed the message over,
  before that work. After ``t0 + seconds`` it keeps receiving for up to :data:`DRAIN_S`.

The measures, per stream. ``P(x)`` = the newest ID due at time ``x`` (the last ID the collector
had produced from its sensor by then); ``R(x)`` = the highest ID the core had received by ``x``;
at a receipt ``r``, ``P(r) − R(r)`` is 0 exactly when the core has the newest message and ``n``
when ``n`` newer ones had already been produced.

- **ID difference** of second ``t`` (``[t0 + t, t0 + t + 1)``, one value per second: the paper's
  Figures 10/11) = the largest ``P(r) − R(r)`` over the core's receipts in that second (``P − R``
  at the second's end if it received nothing of the stream). It is evaluated *at receipts*, not
  at an arbitrary instant: a snapshot at the second boundary would count a message merely in
  flight (0.1–1 ms on shared memory) as one ID of difference whenever the boundary falls between
  hand-over and receipt — about latency × rate of the seconds, some 20 over 30 minutes for a
  60 Hz stream, error that is not there. It is the largest rather than the last receipt's value
  so that a lag inside the second is not hidden by a timely last message (``id_diff_last`` in
  the JSON, and ``cumulative_error_last``, is the literal "last ID produced minus last ID
  received" at the last receipt).
- **cumulative error** = the sum of the ID difference over the seconds: the paper's figures plot
  the ID difference per second and its Table 5 accumulates "errors" over 30 minutes (24,889 for
  the legacy path ≈ 14 per second — the size of a lag of a dozen IDs behind a congested pipe,
  not of a count of dropped messages at 60 Hz). It is the lag in IDs, blind to a message lost
  when the next one still arrived on time, so it is always reported with:
- **lost** = messages due but never delivered, split into *skipped at the collector*, *unsent at
  the end* (in the collector's buffer when the run stopped) and *lost in transport* (handed over,
  never received: keep-latest drops, or still queued when the drain ended).
- **late** = delivered messages received after the next message of their stream was due (the
  messages that make the ID difference non-zero).
- **latency** = receipt − due time (capture to core), p50 / p99 / max; split into **collector
  delay** (hand-over − due: the collector itself was late, p99) and **transport** (receipt −
  hand-over, p99 / max).

The target (issue 6) for redrive: cumulative error 0 *and* nothing lost, at 1× and 10×, over 30
minutes: every message delivered, each before the next one of its stream was due. Configurations
run one after the other — for each rate factor, every chain in turn — never at the same time.
"""

from __future__ import annotations

from benchmarks.loss.machine import wakeup_probe
from benchmarks.loss.measures import StreamLoss, measure_stream
from benchmarks.loss.outputs import plot_loss, table_markdown, write_outputs
from benchmarks.loss.results import ConfigResult, LossBenchResult
from benchmarks.loss.run import bench_loss, run_configuration
from benchmarks.loss.streams import CHAINS, STREAMS, StreamSpec, due_times
from benchmarks.loss.streams import SLOTS as SLOTS

__all__ = [
    "CHAINS",
    "STREAMS",
    "ConfigResult",
    "LossBenchResult",
    "StreamLoss",
    "StreamSpec",
    "bench_loss",
    "due_times",
    "measure_stream",
    "plot_loss",
    "run_configuration",
    "table_markdown",
    "wakeup_probe",
    "write_outputs",
]
