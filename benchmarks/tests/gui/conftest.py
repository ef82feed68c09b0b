"""The GUI test set-up of ``tests/gui/conftest.py`` (Qt attributes before the QApplication, a
skip without an X display, garbage collected between tests) for ``python -m benchmarks gui``."""

from __future__ import annotations

from tests.gui.conftest import _collect_between_tests, _display

__all__ = ["_collect_between_tests", "_display"]
