"""GUI tests: pytest-qt under Xvfb (``make test`` runs the suite under ``xvfb-run -a``).

The Qt attributes that must precede the QApplication (shared GL contexts, pyqtgraph's row-major
images) are set here, before pytest-qt's ``qapp`` fixture creates it.  Each test module starts
with ``pytest.importorskip("PySide6")``; without an X display the tests skip, saying why: GL views
do not work with ``QT_QPA_PLATFORM=offscreen`` (NOTES.md).
"""

from __future__ import annotations

import gc
import importlib.util
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

_HAVE_QT = all(importlib.util.find_spec(m) is not None for m in ("PySide6", "pyqtgraph"))

if _HAVE_QT:
    from redrive.gui.app import configure_qt

    configure_qt()


@pytest.fixture(autouse=True, scope="session")
def _display() -> None:
    # Session scope: it must run before pytest-qt's session-scoped ``qapp``, which aborts the
    # process when Qt finds no display.
    if not os.environ.get("DISPLAY"):
        pytest.skip("no X display: run the GUI tests under `xvfb-run -a pytest` (make test does)")


@pytest.fixture(autouse=True)
def _collect_between_tests() -> Iterator[None]:
    """Collect the garbage of a test (closed windows, GL items, stopped feeds) when it ends,
    while no other window paints and no worker runs: Qt/GL objects finalised at a random later
    point — inside another window's GL paint — can block.

    The objects alive when the test starts (imports, plugins, kernels, earlier tests' survivors —
    their garbage was collected at their ends) are frozen out of that collection's walk
    (``gc.freeze``, as the engine's ``setup_frozen`` does for a run): a walk of the whole heap
    took 1.5–2.8 s a test late in a (loaded) run of the suite, the walk of what it made ms."""
    gc.freeze()
    try:
        yield
    finally:
        gc.collect()
        gc.unfreeze()


@pytest.fixture
def window(qtbot: Any, tmp_path: Path) -> Any:
    """A shown main window with its own settings file (not the user's)."""
    from PySide6 import QtCore

    from redrive.gui.mainwindow import MainWindow

    settings = QtCore.QSettings(str(tmp_path / "gui.ini"), QtCore.QSettings.Format.IniFormat)
    win = MainWindow(settings=settings)
    qtbot.addWidget(win)
    win.show()
    qtbot.waitExposed(win)
    return win
