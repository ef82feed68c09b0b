"""``python -m redrive`` — the same as the ``redrive`` command."""

from __future__ import annotations

from redrive.cli.main import main

raise SystemExit(main())
