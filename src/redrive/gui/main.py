"""``run_gui``: create the application and the main window, open a path, run the event loop."""

from __future__ import annotations

from pathlib import Path

from redrive.gui.app import ensure_app
from redrive.gui.mainwindow import MainWindow

__all__ = ["run_gui"]


def run_gui(path: Path | None = None) -> int:
    """Show the main window (on ``path`` when given) until it is closed; the exit status."""
    app = ensure_app()
    window = MainWindow()
    window.show()
    if path is not None:
        window.open_path(path)
    return int(app.exec())
