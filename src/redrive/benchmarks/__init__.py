"""The benchmarks behind ``redrive bench …``: each compares redrive with a baseline measured in
the same run and prints ratios; results and the machines they came from are in ``BENCHMARKS.md``.

This package sits above the core (it imports whatever it measures) and below the CLI, which
imports it only to register ``redrive bench``; nothing in the core imports it (pyproject.toml's
import contracts).

- :mod:`~redrive.benchmarks.read` (``bench read``): reading and decoding every PointCloud2 of a
  log against iterating the same messages raw with ``rosbags`` / ``mcap``, each pass in a fresh
  interpreter (:mod:`~redrive.benchmarks.passes`); :mod:`~redrive.benchmarks.synth_log` writes
  large logs to run it on;
- :mod:`~redrive.benchmarks.lidar` (``bench lidar``): the simulated LiDAR against Open3D;
- :mod:`~redrive.benchmarks.engine` (``bench engine``): the engine against a bare loop;
- :mod:`~redrive.benchmarks.closed_loop` (``bench closed-loop``): a closed-loop run, its
  real-time factor and the split simulation / algorithms / other, against the world alone;
- :mod:`~redrive.benchmarks.eval` (``bench eval``): nuScenes detection, vectorised against loops;
- :mod:`~redrive.benchmarks.transport` (``bench transport``): the shared-memory channel against
  pipes, queues, ZeroMQ, eCAL and iceoryx2;
- :mod:`~redrive.benchmarks.loss` (``bench loss``): the paper's message-loss experiment;
- :mod:`~redrive.benchmarks.record` (``bench record``): ``redrive live --record`` against
  ``rosbag record`` on one playback: messages lost, CPU of each process tree;
- :mod:`~redrive.benchmarks.export` (``bench export``): the demo run's Foxglove MCAP export
  against copying its log with the ``mcap`` library alone;
- :mod:`~redrive.benchmarks.gui` (``bench gui``, the only Qt part): the main window's frame rate;
- :mod:`~redrive.benchmarks.cli`: the argument parsers and reports.
"""

from __future__ import annotations
