"""``BATCH/batch.json``: the matrix of a batch and where each of its cells stands.

:class:`BatchManifest` is typed like :class:`redrive.results.RunManifest`; it is rewritten
atomically (temp file + ``os.replace``) at every cell event, so a killed batch leaves a readable
file.  Each cell also has ``BATCH/cells/<cell id>.json`` (a :class:`CellRecord`), written by the
process that ran it when it finished: it holds the cell's key (log, pipeline hash, redrive
version) that decides whether a re-run skips it.
"""

from __future__ import annotations

import enum
import json
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError
from redrive.results.manifest import HostInfo, write_json_atomic

__all__ = [
    "BATCH_MANIFEST",
    "BATCH_SCHEMA_VERSION",
    "BatchManifest",
    "CellKey",
    "CellRecord",
    "CellStatus",
    "read_batch_manifest",
    "read_cell_record",
    "write_batch_manifest",
    "write_cell_record",
]

BATCH_MANIFEST = "batch.json"
BATCH_SCHEMA_VERSION = 1


class CellStatus(enum.StrEnum):
    """Where a cell stands: ``pending`` → ``running`` → ``complete`` | ``failed``;
    ``skipped`` (complete from an earlier run of the batch); ``interrupted`` (Ctrl-C)."""

    PENDING = "pending"
    RUNNING = "running"
    COMPLETE = "complete"
    FAILED = "failed"
    SKIPPED = "skipped"
    INTERRUPTED = "interrupted"


@dataclass(frozen=True, slots=True, kw_only=True)
class CellKey:
    """What makes two runs of a cell the same: the log (its sha256; a scenario: name, seed and
    duration), the pipeline's hash (:func:`redrive.batch.spec.pipeline_hash`), redrive's
    version, and the loop's options."""

    log: str
    pipeline_hash: str
    redrive_version: str
    options: str = ""


@dataclass(frozen=True, slots=True, kw_only=True)
class CellRecord:
    """One cell: a log × a pipeline × a loop mode, run into ``run_dir`` (relative to the batch).

    Attributes:
        error: why it failed (``Type: message``, or how its worker died).
        attempts: how many times it was started in this batch run (retries of a dead worker).
        wall_s: seconds its last attempt took.
        step_errors: failed or timed-out algorithm steps of a complete run.
    """

    cell_id: str
    log_id: str
    log: str
    pipeline: str
    loop: str
    run_dir: str
    status: CellStatus
    key: CellKey | None = None
    error: str | None = None
    attempts: int = 0
    wall_s: float | None = None
    frames: int | None = None
    step_errors: int = 0
    finished: str | None = None

    def to_json(self) -> dict[str, Any]:
        out = {f.name: getattr(self, f.name) for f in fields(self)}
        out["status"] = self.status.value
        out["key"] = None if self.key is None else _asdict(self.key)
        return out

    @classmethod
    def from_json(cls, data: Any, *, path: Path) -> CellRecord:
        if not isinstance(data, Mapping):
            raise _error(path, "a cell is not a JSON object")
        try:
            key = data.get("key")
            return cls(
                cell_id=str(data["cell_id"]),
                log_id=str(data["log_id"]),
                log=str(data["log"]),
                pipeline=str(data["pipeline"]),
                loop=str(data["loop"]),
                run_dir=str(data["run_dir"]),
                status=CellStatus(data["status"]),
                key=None if key is None else CellKey(**{k: str(v) for k, v in key.items()}),
                error=data.get("error"),
                attempts=int(data.get("attempts", 0)),
                wall_s=data.get("wall_s"),
                frames=data.get("frames"),
                step_errors=int(data.get("step_errors", 0)),
                finished=data.get("finished"),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as err:
            raise _error(path, f"a cell is malformed ({type(err).__name__}: {err})") from err


@dataclass(frozen=True, slots=True, kw_only=True)
class BatchManifest:
    """``BATCH/batch.json``.

    Attributes:
        spec: the matrix (:meth:`redrive.batch.spec.BatchSpec.to_json`).
        executor, workers, retries, address: how it ran.
        status: ``running`` until every cell has finished, then ``complete`` (no cell failed),
            ``failed`` (some did) or ``interrupted``.
        cells: every cell of the matrix, in matrix order (pipeline, loop, log).
    """

    redrive_version: str
    created: str
    updated: str
    status: str
    host: HostInfo
    spec: Mapping[str, Any]
    executor: str
    workers: int
    retries: int
    cells: tuple[CellRecord, ...]
    address: str | None = None
    finished: str | None = None
    schema_version: int = BATCH_SCHEMA_VERSION
    counts: Mapping[str, int] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        counts = {s.value: 0 for s in CellStatus}
        for cell in self.cells:
            counts[cell.status.value] += 1
        return {
            "schema_version": self.schema_version,
            "redrive_version": self.redrive_version,
            "created": self.created,
            "updated": self.updated,
            "finished": self.finished,
            "status": self.status,
            "host": _asdict(self.host),
            "executor": self.executor,
            "workers": self.workers,
            "retries": self.retries,
            "address": self.address,
            "spec": dict(self.spec),
            "counts": counts,
            "cells": [c.to_json() for c in self.cells],
        }

    @classmethod
    def from_json(cls, data: Any, *, path: Path) -> BatchManifest:
        if not isinstance(data, Mapping):
            raise _error(path, "is not a JSON object")
        version = data.get("schema_version")
        if version != BATCH_SCHEMA_VERSION:
            raise _error(path, f"has schema_version {version!r}; this redrive reads 1")
        try:
            return cls(
                redrive_version=str(data["redrive_version"]),
                created=str(data["created"]),
                updated=str(data["updated"]),
                finished=data.get("finished"),
                status=str(data["status"]),
                host=HostInfo(**data["host"]),
                executor=str(data["executor"]),
                workers=int(data["workers"]),
                retries=int(data["retries"]),
                address=data.get("address"),
                spec=dict(data["spec"]),
                counts=dict(data.get("counts", {})),
                cells=tuple(CellRecord.from_json(c, path=path) for c in data["cells"]),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise _error(path, f"is malformed ({type(err).__name__}: {err})") from err


def _asdict(obj: Any) -> dict[str, Any]:
    return {f.name: getattr(obj, f.name) for f in fields(obj)}


def _error(path: Path, what: str) -> ConfigError:
    return ConfigError(
        f"{path} {what}: it is not a batch manifest redrive wrote, or it is damaged "
        "(re-run the batch into a new directory)"
    )


def write_batch_manifest(batch_dir: Path, manifest: BatchManifest) -> None:
    """Write ``BATCH/batch.json`` atomically."""
    write_json_atomic(batch_dir / BATCH_MANIFEST, manifest.to_json())


def read_batch_manifest(batch_dir: Path) -> BatchManifest:
    """The manifest of the batch in ``batch_dir``.

    Raises:
        ConfigError: there is none, it is not JSON, or a field is missing or malformed.
    """
    path = batch_dir / BATCH_MANIFEST
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as err:
        msg = f"{batch_dir} is not a redrive batch: it has no {BATCH_MANIFEST}"
        raise ConfigError(msg) from err
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise _error(path, f"cannot be read as JSON ({err})") from err
    return BatchManifest.from_json(data, path=path)


def write_cell_record(path: Path, record: CellRecord) -> None:
    """Write a cell's record atomically (the worker does, when its cell has finished)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, record.to_json())


def read_cell_record(path: Path) -> CellRecord | None:
    """The cell record at ``path``, or None when there is none or it is unreadable (the cell
    then runs again)."""
    try:
        return CellRecord.from_json(json.loads(path.read_text(encoding="utf-8")), path=path)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, ConfigError):
        return None
