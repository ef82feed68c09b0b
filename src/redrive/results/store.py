"""Writing and reading a run directory (layout: see :mod:`redrive.results`).

Crash safety: every part is written to a ``*.tmp`` file, fsynced and renamed into place (a
flush's files are fsynced together, then renamed in order:
:func:`~redrive.results._files.write_files`); within one flush the ``frames`` part is renamed
last (then the manifest), so a part of any table counts only when the ``frames`` part of the
same number exists.  A killed writer therefore leaves complete flushes plus, at most, orphan
parts and temp files of the flush it was in: readers ignore them, a resume deletes them.
"""

from __future__ import annotations

import json
import logging
import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from types import TracebackType
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

from redrive.errors import ConfigError, DiskFullError, is_no_space
from redrive.results._buffers import TableBuffers
from redrive.results._files import json_bytes, write_files
from redrive.results._parts import PART_RE, part_name, parts_on_disk, read_part
from redrive.results.manifest import (
    MANIFEST_NAME,
    ResumeRecord,
    RunManifest,
    RunSetup,
    RunStatus,
    RunSummary,
    host_info,
    now_iso,
    read_manifest,
    write_manifest,
)
from redrive.results.records import FrameRecord, ResourceSample
from redrive.results.resume import resume_mismatches, with_resume
from redrive.results.roadmap import MAP_NAME, write_road_map
from redrive.results.run import Run, open_run
from redrive.results.schema import SCHEMAS, TABLES
from redrive.results.summary import summarize_steps
from redrive.types import RoadMap

try:  # POSIX: an advisory lock keeps two writers out of one run directory
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None  # type: ignore[assignment]

__all__ = ["FINAL_STATUSES", "Run", "RunWriter", "open_run"]

#: said on every resume: a plugin's memory (a tracker's tracks, a planner's history) is not stored
RESUME_FRESH_STATE = (
    "resuming after %d frames done: the algorithms start from a fresh state at the first frame "
    "not done (a tracker's tracks, a planner's memory are not restored), so results after the "
    "resume point can differ from those of an uninterrupted run"
)
logger = logging.getLogger(__name__)

#: the statuses :meth:`RunWriter.close` accepts.
FINAL_STATUSES = (RunStatus.COMPLETE, RunStatus.INTERRUPTED, RunStatus.FAILED)
_LOCK_NAME = ".lock"
#: entries a directory may hold and still count as empty (what a writer leaves before its manifest)
_IGNORABLE = {_LOCK_NAME, MANIFEST_NAME + ".tmp"}


class _DirLock:
    """An exclusive advisory lock on ``RUN/.lock`` (released by close or process death)."""

    def __init__(self, run_dir: Path) -> None:
        self._fd: int | None = None
        if fcntl is None:  # pragma: no cover
            return
        fd = os.open(run_dir / _LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            msg = (
                f"{run_dir}: another process is writing this run; wait for it to finish or "
                "write to another --out"
            )
            raise ConfigError(msg) from err
        self._fd = fd

    def release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)  # closing the descriptor drops the flock
            self._fd = None


def _is_empty_dir(path: Path) -> bool:
    return all(entry.name in _IGNORABLE for entry in path.iterdir())


class RunWriter:
    """Writes one run directory: buffered frames → one Parquet part per table per flush.

    Args:
        run_dir: the run directory; created for a new run.
        setup: what the engine knows about the run (log, pipeline, algorithms, seed, sensors).
        resume: continue the run already in ``run_dir`` (its manifest must match ``setup`` in
            :data:`redrive.results.resume.RESUME_KEYS`); a missing or empty directory starts
            a new run.
        flush_every: frames buffered before a flush writes them.
        flush_interval_s: a flush also happens when this long has passed since the last one
            (with at least one frame buffered), so a slow run loses little when killed.

    Raises:
        ConfigError: ``run_dir`` is not empty and not a run (or is a run and ``resume`` is
            False), the run to resume does not match, or another process is writing it.

    One thread writes; the writer holds ``RUN/.lock`` until :meth:`close`.  As a context
    manager it closes with ``complete`` on a normal exit, ``interrupted`` on
    KeyboardInterrupt and ``failed`` on any other exception (recorded in ``manifest.error``).
    """

    def __init__(
        self,
        run_dir: str | Path,
        *,
        setup: RunSetup,
        resume: bool = False,
        flush_every: int = 1000,
        flush_interval_s: float = 2.0,
    ) -> None:
        if flush_every < 1:
            msg = f"RunWriter.flush_every must be >= 1, got {flush_every}"
            raise ValueError(msg)
        self.path = Path(run_dir)
        self.flush_every = int(flush_every)
        self.flush_interval_s = float(flush_interval_s)
        path = self.path
        if path.exists() and not path.is_dir():
            msg = f"{path} is a file, not a run directory; choose another --out"
            raise ConfigError(msg)
        is_run = (path / MANIFEST_NAME).is_file()
        empty = not path.exists() or _is_empty_dir(path)
        if not resume and is_run:
            msg = f"{path} already holds a run; use --resume to continue it or choose another --out"
            raise ConfigError(msg)
        if not is_run and not empty:
            msg = (
                f"{path} is not empty and holds no redrive run; choose another --out "
                "(an empty or new directory), or --resume an existing run directory"
            )
            raise ConfigError(msg)
        path.mkdir(parents=True, exist_ok=True)
        self._lock = _DirLock(path)
        # pyarrow imports pandas (0.3-0.5 s) on its first conversion of Python values: pay that
        # now rather than at the first flush, in the middle of the frames (a live run's frames
        # would come late, a benchmark's frame loop would carry it)
        pa.array([], type=pa.int64())
        self._buffers = TableBuffers()
        self._buffered: set[int] = set()
        self._has_resources = False
        self._done: set[int] = set()
        self._next_part = 0
        self._closed = False
        # what the summary at close reads, kept from this writer's flushes instead of read back
        # from its parts: the summary columns of ``steps`` and ``frames.late`` of each flush
        self._kept_steps: list[pa.Table] = []
        self._kept_late: list[pa.Table] = []
        try:
            if is_run:
                self._manifest = self._open_existing(setup)
            else:
                self._manifest = self._start_new(setup)
        except BaseException:
            self._lock.release()
            raise
        self._parts_before = self._next_part  # parts a resumed run had before this writer
        # the flush interval counts from here: opening (pyarrow's first conversion, the manifest's
        # fsync) can take seconds on a loaded machine and is no flush
        self._last_flush = time.monotonic()

    # -- opening -----------------------------------------------------------------------------

    def _start_new(self, setup: RunSetup) -> RunManifest:
        manifest = RunManifest.start(setup)
        for name in TABLES:
            (self.path / name).mkdir(exist_ok=True)
        write_manifest(self.path, manifest)
        logger.info("new run in %s", self.path)
        return manifest

    def _open_existing(self, setup: RunSetup) -> RunManifest:
        manifest = read_manifest(self.path)
        diffs = resume_mismatches(manifest, setup)
        if diffs:
            msg = (
                f"cannot resume {self.path}: it was run with other inputs ("
                + "; ".join(diffs)
                + "); resume with the same log, algorithms, configs and frame range, or write "
                "to another --out"
            )
            raise ConfigError(msg)
        committed = parts_on_disk(self.path, "frames")
        removed = 0
        for name in TABLES:
            folder = self.path / name
            folder.mkdir(exist_ok=True)
            for entry in folder.iterdir():
                m = PART_RE.match(entry.name)
                orphan = m is not None and int(m.group(1)) not in committed
                if entry.name.endswith(".tmp") or orphan:
                    entry.unlink()
                    removed += 1
        for entry in self.path.glob("*.tmp"):
            entry.unlink()
            removed += 1
        done: set[int] = set()
        for part in committed.values():
            col = read_part(part, SCHEMAS["frames"], ["frame_index"]).column("frame_index")
            done.update(col.to_pylist())
        self._done = done
        self._next_part = max(committed, default=-1) + 1
        record = ResumeRecord(
            at=now_iso(),
            previous_status=manifest.status,
            frames_done=len(done),
            hostname=host_info().hostname,
            removed_incomplete_files=removed,
        )
        manifest = with_resume(manifest, record)
        write_manifest(self.path, manifest)
        logger.info(
            "resuming %s: %d frames done, %d incomplete files removed",
            self.path,
            len(done),
            removed,
        )
        logger.warning(RESUME_FRESH_STATE, len(done))
        return manifest

    # -- writing -----------------------------------------------------------------------------

    @property
    def done_frames(self) -> frozenset[int]:
        """Frame indices already committed to disk (buffered frames are not included)."""
        return frozenset(self._done)

    @property
    def manifest(self) -> RunManifest:
        return self._manifest

    def _check_open(self) -> None:
        if self._closed:
            msg = f"RunWriter for {self.path} is closed"
            raise ValueError(msg)

    def write_frame(self, record: FrameRecord) -> None:
        """Buffer one frame's record; flushes every ``flush_every`` frames.

        Raises:
            ValueError: the frame index was already written in this run.
        """
        if self._closed:  # (_check_open, inline: this is called per frame)
            self._check_open()
        index = record.frame_index
        if index in self._done or index in self._buffered:
            msg = (
                f"frame {index} was already written to {self.path}; skip the frames in "
                "RunWriter.done_frames when resuming"
            )
            raise ValueError(msg)
        self._buffers.add_frame(record)
        self._buffered.add(index)
        if self._buffers.n_frames >= self.flush_every or (
            time.monotonic() - self._last_flush >= self.flush_interval_s
        ):
            self.flush()

    def write_map(self, road_map: RoadMap) -> None:
        """Write the run's road map to ``RUN/map.json`` now (atomically; replaces an earlier one).

        The closed-loop metrics that need road geometry (drivable area, driving direction,
        speed limits) read it; see :mod:`redrive.results.roadmap` for the format.
        """
        self._check_open()
        try:
            write_road_map(self.path, road_map)
        except OSError as err:
            if not is_no_space(err):
                raise
            raise self._out_of_space(err, [(self.path / MAP_NAME, b"")]) from err

    def write_resources(self, samples: Sequence[ResourceSample]) -> None:
        """Buffer resource samples; they are written with the next flush."""
        self._check_open()
        self._buffers.add_resources(samples)
        self._has_resources = True

    def flush(self) -> None:
        """Write what is buffered as one new part per table (``frames`` last), then the manifest."""
        self._check_open()
        parts = self._take_parts()
        if parts is None:
            return
        files, done = parts
        self._commit(files, done, lambda: replace(self._manifest, frames_done=len(done)))

    def _take_parts(self) -> tuple[list[tuple[Path, pa.Table | bytes]], set[int]] | None:
        """The buffered frames as the next flush's parts (``frames`` last) and the frames done
        once they are written; None when nothing is buffered."""
        if not self._buffered and not self._has_resources:
            return None
        self._last_flush = time.monotonic()
        tables = self._buffers.take()
        self._kept_late.append(tables["frames"].select(("late",)))
        if "steps" in tables:
            self._kept_steps.append(tables["steps"].select(_SUMMARY_STEP_COLUMNS))
        number = self._next_part
        files: list[tuple[Path, pa.Table | bytes]] = [
            (self.path / name / part_name(number), table)  # SCHEMAS order: frames last
            for name, table in tables.items()
        ]
        return files, self._done | self._buffered

    def _commit(
        self,
        files: list[tuple[Path, pa.Table | bytes]],
        done: set[int],
        manifest: Callable[[], RunManifest],
    ) -> None:
        """Write a flush's parts and then the manifest ``manifest()`` makes (made while the
        parts are encoded; all fsynced, then renamed in order: the parts, ``frames`` last, then
        the manifest), and count the flush as done."""
        made: list[RunManifest] = []

        def manifest_file() -> tuple[Path, bytes]:
            made.append(manifest())
            return self.path / MANIFEST_NAME, json_bytes(made[0].to_json())

        try:
            write_files(files, last=manifest_file)
        except OSError as err:
            if not is_no_space(err):
                raise
            raise self._out_of_space(err, files) from err
        if files:
            logger.debug("%s: part %d, %d frames", self.path, self._next_part, len(self._buffered))
            self._next_part += 1
        self._done = done
        self._buffered = set()
        self._has_resources = False
        self._manifest = made[0]

    def _out_of_space(
        self, err: OSError, files: list[tuple[Path, pa.Table | bytes]]
    ) -> DiskFullError:
        """A flush found the disk full: nothing of it counts (its renames come after every
        write, the manifest last), so the run holds the frames of the flushes before, intact."""
        where = err.filename or (files[0][0] if files else self.path / MANIFEST_NAME)
        frames = len(self._done)
        msg = (
            f"{self.path}: no space left writing {where} ({err.strerror or err}): the run holds "
            f"the {frames} frames stored before, intact; free some space and continue it with "
            "the same command and --resume"
        )
        self._manifest = replace(self._manifest, error="no space left on the disk")
        return DiskFullError(msg, path=str(where), kept=str(self.path))

    def close(self, *, status: RunStatus, summary: Mapping[str, Any] | None = None) -> None:
        """Flush, then mark the run ``complete``, ``interrupted`` or ``failed``.

        The manifest's ``summary`` holds ``frames``, ``late_frames`` and per-algorithm counts
        and latencies computed from the stored tables, overlaid with ``summary`` (keys of
        :class:`~redrive.results.manifest.RunSummary`).  Closing a closed writer does nothing.

        Raises:
            ValueError: ``status`` is not final, or ``summary`` has a key or value that
                :class:`~redrive.results.manifest.RunSummary` does not take.
        """
        if self._closed:
            return
        if status not in FINAL_STATUSES:
            shown = ", ".join(s.value for s in FINAL_STATUSES)
            msg = f"RunWriter.close: status {str(status)!r} is not one of {shown}"
            raise ValueError(msg)
        extra = _jsonable(summary or {})
        self._summary({"frames": 0, "late_frames": 0, **extra})  # refused before closing
        try:
            # the last flush's parts and the closing manifest are written together; its summary
            # is computed from the tables kept in memory, this flush's included
            files, done = self._take_parts() or ([], self._done)

            def closing() -> RunManifest:
                computed = _computed_summary(
                    self._columns("frames", ("late",), self._kept_late),
                    self._columns("steps", _SUMMARY_STEP_COLUMNS, self._kept_steps),
                )
                return replace(
                    self._manifest,
                    frames_done=len(done),
                    summary=self._summary({**computed, **extra}),
                    status=RunStatus(status),
                    finished=now_iso(),
                )

            self._commit(files, done, closing)
        finally:
            self._closed = True
            self._lock.release()

    def __enter__(self) -> RunWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc_type is None:
            self.close(status=RunStatus.COMPLETE)
            return
        if issubclass(exc_type, KeyboardInterrupt):
            status = RunStatus.INTERRUPTED
        else:
            status = RunStatus.FAILED
            self._manifest = replace(self._manifest, error=f"{exc_type.__name__}: {exc}")
        try:
            self.close(status=status)
        except DiskFullError:  # the disk is still full: the last manifest written stays
            logger.debug("could not close the run in %s", self.path, exc_info=True)
        except Exception:  # never hide the exception that ended the run
            logger.exception("could not close the run in %s after %s", self.path, exc_type)

    def _columns(self, name: str, columns: Sequence[str], kept: list[pa.Table]) -> pa.Table:
        """``columns`` of table ``name`` over the whole run, in part order, as
        :meth:`Run.raw_columns` reads them: the parts a resumed run had before this writer
        read back, then the tables this writer flushed (kept in memory, not read back)."""
        schema = SCHEMAS[name]
        tables = []
        if self._parts_before:
            committed = parts_on_disk(self.path, "frames")
            tables = [
                read_part(path, schema, columns)
                for number, path in parts_on_disk(self.path, name).items()
                if number < self._parts_before and number in committed
            ]
        tables += kept
        if tables:
            return pa.concat_tables(tables)
        return pa.schema([schema.field(c) for c in columns]).empty_table()

    def _summary(self, data: dict[str, Any]) -> RunSummary:
        unknown = sorted(set(data) - set(RunSummary.__dataclass_fields__))
        if unknown:
            msg = f"RunWriter.close: summary keys {unknown} are not fields of RunSummary"
            raise ValueError(msg)
        try:
            return RunSummary.from_json(data, path=self.path / MANIFEST_NAME)
        except ConfigError as err:
            raise ValueError(f"RunWriter.close: {err}") from err


def _jsonable(data: Mapping[str, Any]) -> dict[str, Any]:
    """``data`` through JSON (tuples become lists), so it compares with a manifest read back."""
    try:
        out = json.loads(json.dumps(dict(data), allow_nan=False))
    except (TypeError, ValueError) as err:
        msg = f"run manifest/summary must be JSON-serialisable (no NaN): {err}"
        raise ValueError(msg) from err
    assert isinstance(out, dict)
    return out


def _computed_summary(frames: pa.Table, steps: pa.Table) -> dict[str, Any]:
    """The summary of a run from its ``frames.late`` and the summary columns of its ``steps``
    (what ``Run.table("frames")`` and :meth:`Run.summary` give)."""
    late_column = frames.column("late")
    late = int(pc.sum(late_column).as_py() or 0)
    algorithms = summarize_steps(steps).to_pylist()
    return {"frames": len(late_column), "late_frames": late, "algorithms": algorithms}


#: the columns of ``steps`` that :func:`summarize_steps` reads
_SUMMARY_STEP_COLUMNS = (
    "algorithm", "stage", "role", "status", "latency_ns", "cpu_ns", "n_outputs",
)  # fmt: skip
