"""The QApplication: Qt attributes that must be set before it exists, and pyqtgraph options."""

from __future__ import annotations

import sys
from collections.abc import Sequence

from PySide6 import QtCore, QtWidgets

__all__ = ["APP_NAME", "ORG_NAME", "configure_qt", "ensure_app"]

APP_NAME = "redrive"
ORG_NAME = "redrive"


def configure_qt() -> None:
    """Set what must be set before the QApplication is created.

    Several GL views (planview, A/B windows) share one GL context (``AA_ShareOpenGLContexts``);
    pyqtgraph images are row-major like numpy's (``imageAxisOrder``), else they come out
    transposed.
    """
    import pyqtgraph as pg

    QtCore.QCoreApplication.setAttribute(QtCore.Qt.ApplicationAttribute.AA_ShareOpenGLContexts)
    QtCore.QCoreApplication.setOrganizationName(ORG_NAME)
    QtCore.QCoreApplication.setApplicationName(APP_NAME)
    pg.setConfigOptions(imageAxisOrder="row-major", antialias=False)


def ensure_app(argv: Sequence[str] | None = None) -> QtWidgets.QApplication:
    """The running QApplication, created (after :func:`configure_qt`) when there is none."""
    app = QtWidgets.QApplication.instance()
    if isinstance(app, QtWidgets.QApplication):
        return app
    configure_qt()
    return QtWidgets.QApplication(list(argv) if argv is not None else sys.argv[:1])
