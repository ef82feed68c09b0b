"""``python -m benchmarks NAME …``: the benchmarks that are not part of ``redrive bench``."""

from __future__ import annotations

from benchmarks.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
