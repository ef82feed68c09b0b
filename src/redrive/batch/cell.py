"""One cell of a batch — a log × a pipeline × a loop mode — run where the executor puts it.

A :class:`CellTask` holds only strings and paths (the log's path, the pipeline's file or plugin
names, the run directory): workers read the logs themselves and hand back a small
:class:`~redrive.batch.manifest.CellRecord`, also written to the task's ``record_path``.

The closed loop lives beside this package (DESIGN.md L6: ``closedloop | batch``), so a cell runs
it through a :class:`ClosedLoopRunner` given by the caller (the CLI gives
``redrive.closedloop.run.run_closed_loop``); a runner — what executors call in the worker — is a
module-level function ``(CellTask) -> CellRecord`` so that it pickles by name.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from redrive.batch.manifest import CellKey, CellRecord, CellStatus, write_cell_record
from redrive.batch.spec import LogItem, LoopMode, PipelineItem
from redrive.config import PipelineConfig
from redrive.engine.run import RunRequest, run_log
from redrive.engine.stats import RunReport
from redrive.engine.user_map import MapOption
from redrive.errors import ConfigError
from redrive.output.atomic import atomic_path
from redrive.results import TABLES, RunStatus
from redrive.results.manifest import MANIFEST_NAME, now_iso

__all__ = ["CellRunner", "CellTask", "ClosedLoopRunner", "run_cell", "synthetic_log_path"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True, kw_only=True)
class CellTask:
    """What a worker needs to run one cell.

    Attributes:
        cell_id: ``PIPELINE/LOOP/LOG_ID``.
        batch_dir: the batch directory (absolute); the cell's run directory is
            ``BATCH/runs/<cell_id>`` (emptied first: a cell is redone from scratch), its record
            ``BATCH/cells/<cell_id>.json``, a synthetic scenario's log ``BATCH/logs/…``.
    """

    cell_id: str
    batch_dir: str
    log: LogItem
    pipeline: PipelineItem
    loop: LoopMode
    key: CellKey
    duration_s: float | None = None
    agents: str = "replay"
    on_collision: str = "continue"
    fail_fast: bool = False
    attempt: int = 1
    map_file: str | None = None  # recorded logs: --map, its origin, --no-map
    map_origin: tuple[float, float] | None = None
    no_map: bool = False

    @property
    def run_dir(self) -> Path:
        return Path(self.batch_dir) / "runs" / self.cell_id

    @property
    def record_path(self) -> Path:
        return Path(self.batch_dir) / "cells" / f"{self.cell_id}.json"

    def record(self, status: CellStatus, **changes: object) -> CellRecord:
        """A record of this cell with ``status`` (and ``changes``)."""
        values: dict[str, object] = {
            "cell_id": self.cell_id,
            "log_id": self.log.log_id,
            "log": self.log.describe(),
            "pipeline": self.pipeline.name,
            "loop": self.loop,
            "run_dir": f"runs/{self.cell_id}",
            "status": status,
            "key": self.key,
            "attempts": self.attempt,
            **changes,
        }
        return CellRecord(**values)  # type: ignore[arg-type]


class ClosedLoopRunner(Protocol):
    """Runs a closed loop into ``out`` (``target``: a scenario or a log's path)."""

    def __call__(
        self,
        *,
        target: str,
        pipeline: PipelineConfig,
        out: Path,
        seed: int | None,
        duration_s: float | None,
        agents: str,
        on_collision: str = "continue",
        road_map: MapOption | None = None,
    ) -> RunReport: ...


#: what an executor calls in its worker: a module-level function, so that it pickles by name.
CellRunner = Callable[[CellTask], CellRecord]


def synthetic_log_path(task: CellTask) -> Path:
    """Where the open-loop log of a synthetic scenario cell is kept (shared by its pipelines)."""
    suffix = "" if task.duration_s is None else f"_{task.duration_s:g}s"
    return Path(task.batch_dir) / "logs" / f"{task.log.log_id}{suffix}.mcap"


def _synthesize(task: CellTask) -> Path:
    """The scenario's log, simulated once: the same scenario, seed and duration give the same
    bytes, so two workers that race here write the same file (each renames its own temp)."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    path = synthetic_log_path(task)
    if path.is_file():
        return path
    path.parent.mkdir(parents=True, exist_ok=True)
    assert task.log.scenario is not None
    with atomic_path(path, temp=path.with_name(f".{path.stem}.{os.getpid()}.mcap")) as tmp:
        synthesize(
            load_scenario(task.log.scenario), tmp, duration_s=task.duration_s, seed=task.log.seed
        )
    return path


def run_cell(task: CellTask, *, closed_loop: ClosedLoopRunner | None = None) -> CellRecord:
    """Run ``task`` into its run directory and write its record (also returned).  A failure of the
    cell — a log that cannot be read, a pipeline that does not fit it, a failed run — is its
    record's ``error``; only Ctrl-C (``interrupted``) and the process dying escape."""
    started = time.perf_counter()
    run_dir = task.run_dir
    try:
        _clear_run_dir(task)
        report = _run(task, run_dir, closed_loop)
    except KeyboardInterrupt:
        record = task.record(
            CellStatus.INTERRUPTED, wall_s=time.perf_counter() - started, finished=now_iso()
        )
        write_cell_record(task.record_path, record)
        raise
    except Exception as err:  # the cell's failure, whatever raised it: recorded, not raised
        logger.debug("cell %s failed", task.cell_id, exc_info=True)
        record = task.record(
            CellStatus.FAILED,
            error=f"{type(err).__name__}: {err}",
            wall_s=time.perf_counter() - started,
            finished=now_iso(),
        )
    else:
        record = _record_of(task, report, time.perf_counter() - started)
    write_cell_record(task.record_path, record)
    return record


#: what a run directory holds before its manifest is written (a cell killed while starting)
_RUN_START = frozenset({*TABLES, ".lock", MANIFEST_NAME + ".tmp"})


def _clear_run_dir(task: CellTask) -> None:
    """Empty the cell's run directory for a fresh run — only if it is this cell's own
    (``BATCH/runs/PIPELINE/LOOP/LOG_ID``, no link) and holds nothing but a run: nothing a batch
    did not create is ever removed.

    Raises:
        ConfigError: the directory is elsewhere, a link, or holds something that is no run.
    """
    runs = Path(task.batch_dir, "runs")
    parts = task.cell_id.split("/")
    run_dir = task.run_dir
    if len(parts) != 3 or any(not p or p.startswith(".") for p in parts):
        msg = f"cell {task.cell_id!r}: not a PIPELINE/LOOP/LOG name of a cell directory"
        raise ConfigError(msg)
    for folder in (runs, *(runs.joinpath(*parts[: i + 1]) for i in range(3))):
        if folder.is_symlink():
            msg = f"{folder} is a symbolic link: a batch writes its cells only into its own runs/"
            raise ConfigError(msg)
    if run_dir.exists():
        entries = {entry.name for entry in run_dir.iterdir()}
        if MANIFEST_NAME not in entries and not entries <= _RUN_START:
            msg = (
                f"{run_dir} holds files that are no redrive run ({', '.join(sorted(entries)[:3])}"
                "…): the batch removes only the run directories it made; move them away"
            )
            raise ConfigError(msg)
        shutil.rmtree(run_dir)
    run_dir.parent.mkdir(parents=True, exist_ok=True)


def _map_option(task: CellTask) -> MapOption | None:
    """The cell's map option: recorded logs only (a scenario drives on its own map)."""
    if task.log.path is None or not (task.map_file or task.no_map):
        return None
    path = None if task.map_file is None else Path(task.map_file)
    return MapOption(path=path, origin_lat_lon=task.map_origin, disabled=task.no_map)


def _run(task: CellTask, run_dir: Path, closed_loop: ClosedLoopRunner | None) -> RunReport:
    pipeline = task.pipeline.load(fail_fast=task.fail_fast)
    if task.loop == "open":
        log = Path(task.log.path) if task.log.path is not None else _synthesize(task)
        # a batch over mixed logs: the stages a log can feed run, the others are skipped with
        # the reason in the cell's manifest (pipeline.skipped), as `redrive run` does
        road_map = _map_option(task)
        return run_log(
            RunRequest(log=log, pipeline=pipeline, out=run_dir, skip_unfed=True, road_map=road_map)
        )
    if closed_loop is None:
        msg = "this batch runs no closed loop (its runner was given none); use --loop open"
        raise ConfigError(msg)
    target = task.log.path if task.log.path is not None else task.log.scenario
    assert target is not None
    return closed_loop(
        target=target,
        pipeline=pipeline,
        out=run_dir,
        seed=task.log.seed,
        duration_s=task.duration_s,
        agents=task.agents,
        on_collision=task.on_collision,
        **({"road_map": road_map} if (road_map := _map_option(task)) is not None else {}),
    )


def _record_of(task: CellTask, report: RunReport, wall_s: float) -> CellRecord:
    step_errors = sum(a.error + a.timeout for a in report.algorithms)
    common = {
        "wall_s": wall_s,
        "frames": report.frames,
        "step_errors": step_errors,
        "finished": now_iso(),
    }
    if report.status is RunStatus.COMPLETE:
        return task.record(CellStatus.COMPLETE, **common)
    if report.status is RunStatus.INTERRUPTED:
        return task.record(CellStatus.INTERRUPTED, **common)
    error = "the run failed"
    if report.failure is not None:
        index, step = report.failure
        error = (
            f"fail-fast: {step.algorithm} {step.status} on frame {index}: "
            f"{step.error_type}: {step.error_message}"
        )
    return task.record(CellStatus.FAILED, error=error, **common)
