"""The benchmarks behind ``redrive bench …``: what a user measures on their own machine and logs,
each against a baseline measured in the same run; the figures and the machines they came from
are in ``BENCHMARKS.md``.

This package sits above the core (it imports whatever it measures) and below the CLI, which
imports it only to register ``redrive bench``; nothing in the core imports it (pyproject.toml's
import contracts).  Comparisons against peers (iceoryx2, eCAL, ZeroMQ, ``rosbag record``, Open3D,
the Qt frame rate), the loss soak, fleet, batch, export, serve and the A/B and instruction-count
scripts live in the repository's ``benchmarks/`` (not installed; ``make bench`` runs the set).

- :mod:`~redrive.benchmarks.read` (``bench read``): reading and decoding every PointCloud2 of a
  log against iterating the same messages raw with ``rosbags`` / ``mcap``, each pass in a fresh
  interpreter (:mod:`~redrive.benchmarks.passes`);
- :mod:`~redrive.benchmarks.engine` (``bench engine``): the engine against a bare loop;
- :mod:`~redrive.benchmarks.closed_loop` (``bench closed-loop``): a closed-loop run, its
  real-time factor and the split simulation / algorithms / other, against the world alone;
- :mod:`~redrive.benchmarks.transport` (``bench transport``): the shared-memory channel against
  pipe + pickle and memcpy;
- :mod:`~redrive.benchmarks.cli`: the argument parsers and reports.
"""

from __future__ import annotations
