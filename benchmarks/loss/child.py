"""The entry point of every spawned process (the ``multiprocessing`` target) and its roles."""

from __future__ import annotations

import signal
import traceback
from collections.abc import Callable
from typing import Any

from benchmarks.loss.legacy_chain import _bridge_legacy, _collector_legacy, _core_legacy
from benchmarks.loss.process import _raise_exit, _RunSpec, _watch_parent
from benchmarks.loss.redrive_chain import _collector_redrive, _core_redrive

_ROLES: dict[str, Callable[[_RunSpec, dict[str, Any]], None]] = {
    "collector-legacy": _collector_legacy,
    "bridge-legacy": _bridge_legacy,
    "core-legacy": _core_legacy,
    "collector-redrive": _collector_redrive,
    "core-redrive": _core_redrive,
}


def _child_main(role: str, spec: _RunSpec, ipc: dict[str, Any]) -> None:
    """Entry point of every spawned process; each role reports ``("ready", role)`` and
    ``("done", role)`` on the status queue, and this ``("error", role, text)``."""
    signal.signal(signal.SIGTERM, _raise_exit)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C: the parent sets ``stop``
    _watch_parent(ipc["stop"])
    short = role.split("-", 1)[0]
    try:
        _ROLES[role](spec, ipc)
    except BaseException as err:
        if not ipc["stop"].is_set():
            text = f"{type(err).__name__}: {err}\n{traceback.format_exc()}"
            ipc["status"].put(("error", short, text))
        raise SystemExit(1) from None
