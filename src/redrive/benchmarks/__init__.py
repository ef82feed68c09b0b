"""The benchmarks behind ``redrive bench …``: what a user measures on their own machine and logs,
each against a baseline measured in the same run (figures and machines: ``BENCHMARKS.md``):
:mod:`~redrive.benchmarks.read` (``bench read``, each pass in a fresh interpreter,
:mod:`~redrive.benchmarks.passes`), :mod:`~redrive.benchmarks.engine`,
:mod:`~redrive.benchmarks.closed_loop`, :mod:`~redrive.benchmarks.transport` and
:mod:`~redrive.benchmarks.eval`; :mod:`~redrive.benchmarks.cli` holds their parsers and reports.

Above the core (it imports what it measures), below the CLI, which imports it only to register
``redrive bench``.  Comparisons against peers (iceoryx2, eCAL, ZeroMQ, ``rosbag record``, Open3D,
the Qt frame rate), soak and whole-system benchmarks and the A/B and instruction-count scripts
are the repository's ``benchmarks/`` (not installed; ``make bench``).
"""

from __future__ import annotations
