"""Checks made before Qt starts (this module imports no Qt): the ``gui`` extra is installed and
there is a display.  ``redrive gui`` and ``python -m benchmarks gui`` call them so a missing package or a
headless machine is a clear error instead of an ImportError or Qt aborting the process."""

from __future__ import annotations

import importlib.util
import os

from redrive.errors import ConfigError

__all__ = ["require_display", "require_gui"]


def require_gui() -> None:
    """Raise a ConfigError saying how to install the GUI when PySide6/pyqtgraph are missing."""
    missing = [m for m in ("PySide6", "pyqtgraph", "OpenGL") if importlib.util.find_spec(m) is None]
    if missing:
        msg = (
            f"the GUI needs {', '.join(missing)}: install redrive's gui extra "
            "(pip install 'redrive[gui]', or `make gui` in the repository)"
        )
        raise ConfigError(msg)


def require_display() -> None:
    """Raise a ConfigError when Qt would find no display (it aborts the process instead)."""
    if os.environ.get("QT_QPA_PLATFORM"):
        return
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        msg = (
            "no display: `redrive gui` needs a desktop session (DISPLAY or WAYLAND_DISPLAY); on "
            "a headless machine run it under Xvfb: xvfb-run -a redrive gui …"
        )
        raise ConfigError(msg)
