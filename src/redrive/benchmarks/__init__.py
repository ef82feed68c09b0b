"""Benchmarks that compare redrive with a baseline measured in the same run.

:func:`redrive.benchmarks.read.bench_read` times reading and decoding every PointCloud2 of a log
against iterating the same messages raw with ``rosbags`` / ``mcap``;
:func:`redrive.benchmarks.synth_log.write_synthetic_bag` makes large logs to run it on.  The CLI is
``redrive bench read``; results and the machine they came from are in ``BENCHMARKS.md``.
"""

from __future__ import annotations
