"""How redrive puts things out (L1): files written atomically, spreadsheets, progress displays.

* :mod:`redrive.output.atomic` — the one atomic write: a temp file in the same folder, fsync of
  the file, rename, fsync of the folder.
* :mod:`redrive.output.xlsx` — the one XLSX writer (openpyxl, write-only, formula-safe cells).
* :mod:`redrive.output.progress` — the one progress display (rich, with an ETA; silent when
  the terminal is not a TTY).
* :mod:`redrive.output.text` — names from a log made safe to show on a terminal (escape
  sequences and rich markup appear as characters).

Nothing here imports redrive above :mod:`redrive.errors`, so every layer can use it.
"""

from __future__ import annotations

from redrive.output.atomic import atomic_path, fsync_dir, sync_tree, write_atomic

__all__ = ["atomic_path", "fsync_dir", "sync_tree", "write_atomic"]
