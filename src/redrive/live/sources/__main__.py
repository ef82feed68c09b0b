"""``python -m redrive.live.sources``: run one source as its own process."""

from __future__ import annotations

import sys

from redrive.live.sources._cli import main

if __name__ == "__main__":
    sys.exit(main())
