"""The main window's small helpers: the recently opened logs and runs (newest first, kept in
the GUI's QSettings) and the About box."""

from __future__ import annotations

from pathlib import Path

from PySide6 import QtCore, QtWidgets

__all__ = ["RecentPaths", "show_about"]


class RecentPaths:
    """At most ``limit`` paths under the settings key ``recent``."""

    def __init__(self, settings: QtCore.QSettings, limit: int = 8) -> None:
        self.settings = settings
        self.limit = limit

    def paths(self) -> list[str]:
        value = self.settings.value("recent", [])
        if isinstance(value, str):
            return [value]
        return [str(v) for v in value] if isinstance(value, list) else []

    def add(self, path: Path) -> None:
        """Put ``path`` (resolved) first, dropping an older entry of it and the oldest past the
        limit."""
        text = str(path.resolve())
        recent = [text, *(p for p in self.paths() if p != text)][: self.limit]
        self.settings.setValue("recent", recent)


def show_about(parent: QtWidgets.QWidget) -> None:
    """The About box: redrive's version and where its docs are."""
    from redrive import __version__

    QtWidgets.QMessageBox.about(
        parent,
        "About redrive",
        f"redrive {__version__}\nRe-drive autonomous-driving algorithms on recorded or live "
        "sensor data.\nDocs: docs/gui.md in the repository.",
    )
