"""Run a batch: lay out its cells, skip the ones already complete, run the rest, keep the manifest.

>>> manifest = run_batch(spec, Path("batches/nightly"), runner=my_runner)   # doctest: +SKIP
"""

from __future__ import annotations

import fcntl
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from redrive.batch.cell import CellRunner, CellTask
from redrive.batch.executors import LocalExecutor, RayExecutor
from redrive.batch.manifest import (
    BatchManifest,
    CellKey,
    CellRecord,
    CellStatus,
    read_cell_record,
    write_batch_manifest,
)
from redrive.batch.spec import BatchSpec, LogItem, pipeline_hash
from redrive.errors import ConfigError
from redrive.io.content import fingerprint_log
from redrive.results import RunStatus, read_manifest
from redrive.results.manifest import host_info, now_iso, redrive_version

__all__ = ["BatchProgress", "run_batch"]


@dataclass(slots=True)
class BatchProgress:
    """The counts a progress display shows, updated at every cell event."""

    total: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    running: int = 0
    frames: int = 0
    started_at: float = field(default_factory=time.perf_counter)
    walls: list[float] = field(default_factory=list)

    @property
    def finished(self) -> int:
        """Cells that need no more work in this run: complete, failed or skipped."""
        return self.done + self.failed + self.skipped

    def frames_per_s(self, now: float | None = None) -> float | None:
        """Frames of the cells completed in this run per second of batch wall time; None before
        the first one completed."""
        elapsed = (time.perf_counter() if now is None else now) - self.started_at
        if not self.frames or elapsed <= 0:
            return None
        return self.frames / elapsed

    @property
    def remaining(self) -> int:
        return self.total - self.done - self.failed - self.skipped

    def eta_s(self, workers: int) -> float | None:
        """Seconds left: the mean wall time of the cells finished in this run × the cells left,
        over the workers; None before the first cell finished."""
        if not self.walls:
            return None
        mean = sum(self.walls) / len(self.walls)
        left = self.remaining - self.running
        return mean * (max(left, 0) / max(workers, 1)) + mean * 0.5 * min(self.running, 1)


#: what run_batch tells its caller: (event, the cell's record, the counts); events are
#: ``skipped``, ``started``, ``complete``, ``failed``, ``interrupted``.
ProgressCallback = Callable[[str, CellRecord, BatchProgress], None]


class _Throttle:
    """When ``batch.json`` is rewritten while cells run: at most once a second, and never more
    often than every 10× the time the last write took, so that a fleet of thousands of cells
    (a manifest of megabytes) costs the driver at most a tenth of its time. The cells' own
    records (written by the workers) are what a rerun trusts, so a manifest that lags behind by
    a second loses nothing; the final state is always written."""

    def __init__(self, min_interval_s: float = 1.0) -> None:
        self.min_interval_s = min_interval_s
        self.interval_s = 0.0
        self.last = -math.inf

    def due(self) -> bool:
        return time.perf_counter() - self.last >= self.interval_s

    def wrote(self, took_s: float) -> None:
        self.last = time.perf_counter()
        self.interval_s = max(self.min_interval_s, 10.0 * took_s)


def _log_key(item: LogItem, duration_s: float | None, cache: dict[str, str]) -> str:
    if item.path is not None:
        if item.path not in cache:
            cache[item.path] = fingerprint_log(Path(item.path)).sha256
        return cache[item.path]
    scenario = item.scenario or ""
    if scenario.endswith(".toml"):
        import hashlib

        scenario += " sha256 " + hashlib.sha256(Path(scenario).read_bytes()).hexdigest()
    return f"scenario {scenario} seed {item.seed} duration {duration_s}"


def _map_key(spec: BatchSpec) -> str:
    """The map part of a cell's key: the map file's sha256 and origin, or ``no_map``."""
    if spec.no_map or spec.map_file is None:
        return "no_map"
    import hashlib

    digest = hashlib.sha256(Path(spec.map_file).read_bytes()).hexdigest()[:16]
    return f"map={digest}@{spec.map_origin}"


def _is_complete(task: CellTask) -> bool:
    """Whether the cell's run directory is complete for the same key (log, pipeline hash,
    redrive version, options) as ``task``'s."""
    record = read_cell_record(task.record_path)
    if record is None or record.status is not CellStatus.COMPLETE or record.key != task.key:
        return False
    try:
        manifest = read_manifest(task.run_dir)
    except ConfigError:
        return False
    if manifest.status is not RunStatus.COMPLETE:
        return False
    if task.log.path is not None and task.loop == "open":
        return manifest.log.sha256 == task.key.log
    return True


def plan_cells(spec: BatchSpec, out: Path) -> list[CellTask]:
    """Every cell of the matrix, in order pipeline → loop → log, with its key.

    Raises:
        ConfigError: a pipeline cannot be loaded (a missing file, an invalid key).
    """
    version = redrive_version()
    hashes = {p.name: pipeline_hash(p.load(fail_fast=spec.fail_fast)) for p in spec.pipelines}
    log_keys: dict[str, str] = {}
    tasks = []
    for pipeline in spec.pipelines:
        for loop in spec.loops:
            for log in spec.logs:
                options = ""
                if loop == "closed":
                    options = f"agents={spec.agents}"
                    if spec.on_collision != "continue":  # the keys of earlier batches stand
                        options += f",on_collision={spec.on_collision}"
                if log.path is not None and (spec.map_file or spec.no_map):
                    options += f",{_map_key(spec)}"
                key = CellKey(
                    log=_log_key(log, spec.duration_s, log_keys),
                    pipeline_hash=hashes[pipeline.name],
                    redrive_version=version,
                    options=options,
                )
                tasks.append(
                    CellTask(
                        cell_id=f"{pipeline.name}/{loop}/{log.log_id}",
                        batch_dir=str(out.resolve()),
                        log=log,
                        pipeline=pipeline,
                        loop=loop,
                        key=key,
                        duration_s=spec.duration_s,
                        agents=spec.agents,
                        on_collision=spec.on_collision,
                        fail_fast=spec.fail_fast,
                        map_file=spec.map_file,
                        map_origin=spec.map_origin,
                        no_map=spec.no_map,
                    )
                )
    return tasks


def run_batch(
    spec: BatchSpec,
    out: Path,
    *,
    runner: CellRunner,
    executor: str = "local",
    workers: int | None = None,
    retries: int = 1,
    address: str | None = None,
    cpus_per_cell: float = 1.0,
    force: bool = False,
    progress: ProgressCallback | None = None,
) -> BatchManifest:
    """Run every cell of ``spec`` that is not complete yet (all of them with ``force``) into the
    batch directory ``out``, and return its final manifest (also in ``out/batch.json``).

    ``runner`` runs one cell in a worker (:data:`redrive.batch.cell.CellRunner`).  A cell's
    failure is in its record, not raised.

    Raises:
        ConfigError: a pipeline cannot be loaded, Ray is asked for but not installed, or another
            batch is running in ``out``.
        KeyboardInterrupt: after the running cells were stopped and the manifest written.
    """
    workers = workers or os.cpu_count() or 1
    if workers < 1 or retries < 0:
        raise ConfigError("--workers must be >= 1 and --retries >= 0")
    if executor == "local":
        chosen: LocalExecutor | RayExecutor = LocalExecutor(
            workers=workers, retries=retries, threads_per_cell=max(1, round(cpus_per_cell))
        )
    elif executor == "ray":
        chosen = RayExecutor(
            workers=workers, retries=retries, address=address, cpus_per_cell=cpus_per_cell
        )
    else:
        raise ConfigError(f"--executor {executor!r}: expected local or ray")
    out.mkdir(parents=True, exist_ok=True)
    with open(out / ".lock", "w") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError as err:
            msg = f"{out}: another `redrive batch` is running in this directory"
            raise ConfigError(msg) from err
        return _run_locked(
            spec, out, runner=runner, executor=chosen, force=force, progress=progress
        )


def _run_locked(
    spec: BatchSpec,
    out: Path,
    *,
    runner: CellRunner,
    executor: LocalExecutor | RayExecutor,
    force: bool,
    progress: ProgressCallback | None,
) -> BatchManifest:
    tasks = plan_cells(spec, out)
    records: dict[str, CellRecord] = {}
    to_run: list[CellTask] = []
    counts = BatchProgress(total=len(tasks))
    for task in tasks:
        if not force and _is_complete(task):
            old = read_cell_record(task.record_path)
            assert old is not None
            records[task.cell_id] = replace(old, status=CellStatus.SKIPPED)
            counts.skipped += 1
        else:
            records[task.cell_id] = task.record(CellStatus.PENDING, attempts=0)
            to_run.append(task)
    manifest = BatchManifest(
        redrive_version=redrive_version(),
        created=now_iso(),
        updated=now_iso(),
        status="running",
        host=host_info(),
        spec=spec.to_json(),
        executor="ray" if isinstance(executor, RayExecutor) else "local",
        workers=executor.workers,
        retries=executor.retries,
        address=executor.address if isinstance(executor, RayExecutor) else None,
        cells=(),
    )

    throttle = _Throttle()

    def save(status: str = "running", finished: str | None = None) -> None:
        nonlocal manifest
        if status == "running" and not throttle.due():
            return
        started = time.perf_counter()
        manifest = replace(
            manifest,
            cells=tuple(records[t.cell_id] for t in tasks),
            updated=now_iso(),
            status=status,
            finished=finished,
        )
        write_batch_manifest(out, manifest)
        throttle.wrote(time.perf_counter() - started)

    save()
    if progress is not None:
        for task in tasks:
            if records[task.cell_id].status is CellStatus.SKIPPED:
                progress("skipped", records[task.cell_id], counts)

    class Events:
        def started(self, task: CellTask) -> None:
            records[task.cell_id] = task.record(CellStatus.RUNNING)
            counts.running += 1
            save()
            if progress is not None:
                progress("started", records[task.cell_id], counts)

        def finished(self, record: CellRecord) -> None:
            records[record.cell_id] = record
            counts.running -= 1
            if record.status is CellStatus.COMPLETE:
                counts.done += 1
            elif record.status is CellStatus.FAILED:
                counts.failed += 1
            if record.wall_s is not None and record.status is CellStatus.COMPLETE:
                counts.walls.append(record.wall_s)
                counts.frames += record.frames or 0
            save()
            if progress is not None:
                progress(record.status.value, record, counts)

    try:
        executor.run(to_run, runner, Events())
    except BaseException:
        save("interrupted", now_iso())
        raise
    failed = any(
        r.status is not CellStatus.COMPLETE and r.status is not CellStatus.SKIPPED
        for r in records.values()
    )
    save("failed" if failed else "complete", now_iso())
    return manifest
