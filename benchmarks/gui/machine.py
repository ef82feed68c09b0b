"""The machine a GUI benchmark runs on: CPU, versions, Qt platform, screen, GL renderer."""

from __future__ import annotations

import os
from typing import Any

from PySide6 import QtWidgets

from benchmarks.loss.machine import _machine as _machine_base


def _gl_renderer(view: Any) -> str:
    try:
        from OpenGL import GL

        view.makeCurrent()
        text = GL.glGetString(GL.GL_RENDERER)
        view.doneCurrent()
    except Exception:  # pragma: no cover - informational only
        return ""
    return text.decode() if isinstance(text, bytes) else str(text or "")


def _machine(app: QtWidgets.QApplication) -> dict[str, str]:
    import pyqtgraph as pg
    import PySide6

    # cpu, cpus, system, python, numpy and load_average_at_start, as ``python -m benchmarks loss``
    # describes the machine; the load average stays the last key.
    base = _machine_base()
    load = base.pop("load_average_at_start")
    screen = app.primaryScreen()
    geometry = screen.geometry() if screen is not None else None
    return {
        **base,
        "pyside6": PySide6.__version__,
        "pyqtgraph": str(pg.__version__),
        "qt_platform": app.platformName(),
        "screen": "" if geometry is None else f"{geometry.width()}x{geometry.height()}",
        "gl_renderer": "",
        # numpy's OpenBLAS threads spin after each matmul: this changes the figures (BENCHMARKS.md)
        "openblas_num_threads": os.environ.get("OPENBLAS_NUM_THREADS", "unset"),
        "load_average_at_start": load,
    }
