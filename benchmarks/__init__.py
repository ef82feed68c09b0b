"""redrive's benchmarks against peers, the soak and A/B runs: not installed, run from the
repository root with ``PYTHONPATH=src python -m benchmarks NAME …`` (``make bench`` runs the set,
:mod:`benchmarks.suite`); the scripts beside this file run as ``python benchmarks/X.py`` or
``python -m benchmarks.X``.  ``README.md`` lists them, ``../BENCHMARKS.md`` has the figures.

What a user measures on their own machine and logs stays in the package: ``redrive bench read``,
``engine``, ``closed-loop`` and ``transport`` (:mod:`redrive.benchmarks`).  This package imports
redrive; redrive never imports it.
"""
