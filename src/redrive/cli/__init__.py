"""The ``redrive`` command line (layer L6)."""
