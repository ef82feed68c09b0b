"""``manifest.json``: what a run is (log, pipeline, algorithms, seed) and how far it got.

The engine supplies ``log``, ``pipeline``, ``algorithms`` and ``seed`` (and may add more keys);
the store adds ``schema_version``, ``redrive_version``, ``created``/``finished`` (ISO 8601 UTC),
``status``, ``host``, ``frames_done``, ``resumes`` and ``summary``.  Written atomically.
"""

from __future__ import annotations

import json
import os
import platform
import socket
import sys
from collections.abc import Mapping
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError

__all__ = [
    "MANIFEST_NAME",
    "RESUME_KEYS",
    "SCHEMA_VERSION",
    "STORE_KEYS",
    "host_info",
    "now_iso",
    "read_manifest",
    "redrive_version",
    "resume_mismatches",
    "write_json_atomic",
]

MANIFEST_NAME = "manifest.json"
#: version of the run-directory format; bumped on any incompatible change.
SCHEMA_VERSION = 1
#: keys the store owns; an engine-supplied manifest must not set them.
STORE_KEYS = (
    "schema_version",
    "redrive_version",
    "created",
    "finished",
    "status",
    "host",
    "frames_done",
    "resumes",
    "summary",
)
#: what must be equal for a run to be resumed: dotted paths into the manifest; for
#: ``algorithms`` each entry's ``name``, ``version`` and ``config_hash`` are compared in order.
RESUME_KEYS = ("log.sha256", "algorithms", "pipeline.first_frame", "pipeline.stop_frame")
_ALGORITHM_KEYS = ("name", "version", "config_hash")


def now_iso() -> str:
    """The current time, ISO 8601 UTC with milliseconds (``2025-01-31T12:00:00.123+00:00``)."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def redrive_version() -> str:
    try:
        return metadata.version("redrive")
    except metadata.PackageNotFoundError:
        return "unknown"


def host_info() -> dict[str, Any]:
    return {
        "hostname": socket.gethostname(),
        "platform": platform.platform(),
        "python": sys.version.split()[0],
        "cpu_count": os.cpu_count(),
    }


def write_json_atomic(path: Path, data: Mapping[str, Any]) -> None:
    """Write ``data`` as indented JSON to ``path`` through a temp file and ``os.replace``."""
    text = json.dumps(data, indent=2, sort_keys=False, allow_nan=False) + "\n"
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def read_manifest(run_dir: Path) -> dict[str, Any]:
    """The manifest of ``run_dir``; ConfigError when there is none or it cannot be read."""
    path = run_dir / MANIFEST_NAME
    if not path.is_file():
        msg = (
            f"{run_dir} is not a redrive run: it has no {MANIFEST_NAME} "
            "(give the directory a `redrive run --out` wrote)"
        )
        raise ConfigError(msg)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        msg = f"{path}: cannot read the run manifest ({err}); the run directory is damaged"
        raise ConfigError(msg) from err
    if not isinstance(data, dict) or "schema_version" not in data:
        msg = f"{path}: not a redrive run manifest (no schema_version)"
        raise ConfigError(msg)
    if data["schema_version"] != SCHEMA_VERSION:
        msg = (
            f"{path}: run format version {data['schema_version']} is not supported "
            f"(this redrive reads version {SCHEMA_VERSION}); use the redrive that wrote it"
        )
        raise ConfigError(msg)
    return data


_MISSING = object()


def _lookup(data: Mapping[str, Any], dotted: str) -> Any:
    value: Any = data
    for part in dotted.split("."):
        if not isinstance(value, Mapping) or part not in value:
            return _MISSING
        value = value[part]
    return value


def _algorithms_key(value: Any) -> Any:
    if not isinstance(value, list | tuple):
        return value
    return [{k: a.get(k) for k in _ALGORITHM_KEYS} if isinstance(a, Mapping) else a for a in value]


def resume_mismatches(old: Mapping[str, Any], new: Mapping[str, Any]) -> list[str]:
    """Human-readable differences in :data:`RESUME_KEYS` between a run's manifest and a new one."""
    out = []
    for key in RESUME_KEYS:
        a, b = _lookup(old, key), _lookup(new, key)
        if key == "algorithms":
            a, b = _algorithms_key(a), _algorithms_key(b)
        if a != b:
            show_a = "(absent)" if a is _MISSING else json.dumps(a, default=str)
            show_b = "(absent)" if b is _MISSING else json.dumps(b, default=str)
            out.append(f"{key}: run has {show_a}, now {show_b}")
    return out
