"""Where the cells of a batch run: a local pool of processes, or a Ray cluster.

Both run at most ``workers`` cells at a time and call the runner with a
:class:`~redrive.batch.cell.CellTask` (paths, never log bytes).  A worker that dies — killed by a
signal, ``os._exit`` in an algorithm, the OOM killer — fails only its cell, which is run again up
to ``retries`` times; a cell that fails on its own (a corrupt log, a pipeline that does not fit)
is not retried: it would fail the same way.

``local`` starts one process per cell from a ``forkserver`` (redrive, its readers and reference
algorithms are imported once, in the server, and the algorithms' compiled kernels loaded —
:mod:`redrive.batch.preload`; each cell is a fresh fork of it), so one dead process is one
failed cell — unlike a
``concurrent.futures`` pool, which breaks as a whole.  ``ray`` submits one task per cell with
``num_cpus`` per task and Ray's own ``max_retries`` for dead workers; Ray is imported only here,
only when asked for.
"""

from __future__ import annotations

import logging
import multiprocessing
import os
import signal
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from multiprocessing.connection import wait
from typing import Any, Protocol

from redrive.batch._deathsig import die_with_driver
from redrive.batch.cell import CellRunner, CellTask
from redrive.batch.manifest import CellRecord, CellStatus, read_cell_record, write_cell_record
from redrive.errors import ConfigError
from redrive.results.manifest import now_iso

__all__ = ["CellEvents", "LocalExecutor", "RayExecutor", "dead_worker_reason"]

logger = logging.getLogger(__name__)

#: how long an interrupted worker may take to close its run directory before it is killed.
_INTERRUPT_GRACE_S = 20.0


class CellEvents(Protocol):
    """What an executor reports to the batch as cells start and finish."""

    def started(self, task: CellTask) -> None: ...

    def finished(self, record: CellRecord) -> None: ...


def dead_worker_reason(exitcode: int | None) -> str:
    """Why a worker process ended without a record (``exitcode`` as multiprocessing gives it)."""
    if exitcode is not None and exitcode < 0:
        try:
            name = signal.Signals(-exitcode).name
        except ValueError:
            name = f"signal {-exitcode}"
        return f"WorkerDied: the worker process was killed by {name}"
    return f"WorkerDied: the worker process exited with status {exitcode} before finishing the cell"


def _child(runner: CellRunner, task: CellTask, driver_pid: int) -> None:
    """A local worker: run one cell (its record is written by the runner).  It dies with the
    driver (:func:`~redrive.batch._deathsig.die_with_driver`), and leaves the terminal's process group, so that Ctrl-C
    reaches the driver only, which then interrupts each running cell once (:func:`_stop`)."""
    die_with_driver(driver_pid)
    os.setpgrp()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        runner(task)
    except KeyboardInterrupt:
        os._exit(130)


#: the thread pools of the numeric libraries a cell's process sizes from these variables.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def _threads(count: int) -> Iterator[None]:
    """While the forkserver starts: ``count`` threads for OpenMP/OpenBLAS/MKL (variables the
    user set are kept), as Ray does for its workers (``num_cpus``).  Otherwise every cell's
    BLAS would start one thread per core and ``workers`` cells would fight over the cores (2
    workers were slower than 1 on 2 cores: ``python -m benchmarks batch``)."""
    saved = {name: os.environ.get(name) for name in THREAD_VARIABLES}
    for name in THREAD_VARIABLES:
        os.environ.setdefault(name, str(count))
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


@dataclass(frozen=True, slots=True, kw_only=True)
class LocalExecutor:
    """One process per cell, ``workers`` at a time, forked from a forkserver whose numeric
    libraries use ``threads_per_cell`` threads (the forkserver of a process keeps the variables
    it started with)."""

    workers: int
    retries: int = 1
    threads_per_cell: int = 1

    def run(self, tasks: Sequence[CellTask], runner: CellRunner, events: CellEvents) -> None:
        with _threads(self.threads_per_cell):
            self._run(tasks, runner, events)

    def _run(self, tasks: Sequence[CellTask], runner: CellRunner, events: CellEvents) -> None:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(
            ["redrive.batch.preload", "redrive.batch.cell", runner.__module__]
        )
        pending: deque[CellTask] = deque(tasks)
        running: dict[Any, tuple[Any, CellTask]] = {}
        try:
            while pending or running:
                while pending and len(running) < max(1, self.workers):
                    task = pending.popleft()
                    task.record_path.unlink(missing_ok=True)
                    proc = ctx.Process(
                        target=_child,
                        args=(runner, task, os.getpid()),
                        name=f"redrive-batch {task.cell_id}",
                    )
                    proc.start()
                    running[proc.sentinel] = (proc, task)
                    events.started(task)
                for sentinel in wait(list(running)):
                    proc, task = running.pop(sentinel)
                    proc.join()
                    record = read_cell_record(task.record_path)
                    if record is None:
                        reason = dead_worker_reason(proc.exitcode)
                        if task.attempt <= self.retries:
                            logger.warning("%s: %s; retrying", task.cell_id, reason)
                            pending.appendleft(replace(task, attempt=task.attempt + 1))
                            continue
                        record = task.record(CellStatus.FAILED, error=reason, finished=now_iso())
                        write_cell_record(task.record_path, record)
                    events.finished(record)
        except BaseException:
            _stop(running)
            for _proc, task in running.values():
                record = read_cell_record(task.record_path) or task.record(
                    CellStatus.INTERRUPTED, finished=now_iso()
                )
                events.finished(record)
            raise


def _stop(running: dict[Any, tuple[Any, CellTask]]) -> None:
    """Ctrl-C: each running cell gets SIGINT (its run directory is closed as interrupted), then
    SIGKILL if it has not ended within the grace period."""
    for proc, _ in running.values():
        if proc.is_alive() and proc.pid is not None:
            os.kill(proc.pid, signal.SIGINT)
    for proc, _ in running.values():
        proc.join(_INTERRUPT_GRACE_S)
        if proc.is_alive():
            proc.kill()
            proc.join()


def _ray_cell(runner: CellRunner, task: CellTask) -> dict[str, Any]:
    """A Ray task: run one cell where Ray put it; the record comes back as a small dict."""
    return runner(task).to_json()


def _import_ray() -> Any:
    try:
        import ray
    except ImportError as err:
        msg = (
            "--executor ray needs Ray, an optional extra of redrive: "
            "pip install 'redrive[ray]' (or use --executor local)"
        )
        raise ConfigError(msg) from err
    return ray


@dataclass(frozen=True, slots=True, kw_only=True)
class RayExecutor:
    """One Ray task per cell, ``workers`` in flight.

    Attributes:
        address: an existing cluster (``ray://…`` or ``HOST:PORT``, or ``auto``); None starts a
            local one with ``workers`` CPUs (and no dashboard) unless Ray is already initialised
            in this process, and shuts it down at the end.  The batch directory and the logs
            must be on storage every node sees: tasks get paths.
        cpus_per_cell: the ``num_cpus`` of each task.
    """

    workers: int
    retries: int = 1
    address: str | None = None
    cpus_per_cell: float = 1.0

    def run(self, tasks: Sequence[CellTask], runner: CellRunner, events: CellEvents) -> None:
        ray = _import_ray()
        started_here = False
        if not ray.is_initialized():
            if self.address is None:
                ray.init(num_cpus=self.workers, include_dashboard=False, log_to_driver=False)
            else:
                ray.init(address=self.address, log_to_driver=False)
            started_here = True
        try:
            self._run(ray, tasks, runner, events)
        finally:
            if started_here:
                ray.shutdown()

    def _run(
        self, ray: Any, tasks: Sequence[CellTask], runner: CellRunner, events: CellEvents
    ) -> None:
        remote = ray.remote(_ray_cell).options(
            num_cpus=self.cpus_per_cell, max_retries=self.retries, retry_exceptions=False
        )
        pending: deque[CellTask] = deque(tasks)
        running: dict[Any, CellTask] = {}
        try:
            while pending or running:
                while pending and len(running) < max(1, self.workers):
                    task = pending.popleft()
                    task.record_path.unlink(missing_ok=True)
                    running[remote.remote(runner, task)] = task
                    events.started(task)
                ready, _ = ray.wait(list(running), num_returns=1)
                for ref in ready:
                    task = running.pop(ref)
                    try:
                        record = CellRecord.from_json(ray.get(ref), path=task.record_path)
                    except ray.exceptions.RayError as err:
                        first = str(err).strip().splitlines()[0] if str(err).strip() else ""
                        reason = f"{type(err).__name__}: {first}"
                        if isinstance(err, ray.exceptions.WorkerCrashedError):
                            reason = (
                                f"WorkerDied: the Ray worker died "
                                f"({self.retries + 1} attempt(s)): {first}"
                            )
                        record = task.record(
                            CellStatus.FAILED,
                            error=reason,
                            attempts=self.retries + 1,
                            finished=now_iso(),
                        )
                        write_cell_record(task.record_path, record)
                    events.finished(record)
        except BaseException:
            for ref, task in running.items():
                ray.cancel(ref)
                events.finished(task.record(CellStatus.INTERRUPTED, finished=now_iso()))
            raise
