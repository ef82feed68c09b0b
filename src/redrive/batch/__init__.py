"""Batches (L6): many logs × pipelines × loop modes, on a local process pool or a Ray cluster.

``redrive batch`` (:mod:`redrive.cli.batch`) lays out the matrix (:mod:`redrive.batch.spec`),
skips the cells already complete for the same key and runs the rest through an executor
(:mod:`redrive.batch.executors`); each cell is an ordinary run directory
(:mod:`redrive.batch.cell`), so every command that reads a run reads a cell.

Layout of a batch directory (``docs/batch.md``)::

    BATCH/batch.json                          the BatchManifest (redrive.batch.manifest): the
                                              matrix, how it ran, every cell's status and error
    BATCH/runs/PIPELINE/LOOP/LOG_ID/          one ordinary run directory per cell
    BATCH/cells/PIPELINE/LOOP/LOG_ID.json     the cell's record, written by its worker: status,
                                              error, key (log, pipeline hash, redrive version)
    BATCH/logs/SCENARIO@SEED[_Ds].mcap        open-loop logs of synthetic scenarios
    BATCH/.lock                               held while a batch runs in the directory
"""

from __future__ import annotations

from redrive.batch.cell import CellRunner, CellTask, ClosedLoopRunner, run_cell
from redrive.batch.manifest import (
    BATCH_MANIFEST,
    BatchManifest,
    CellKey,
    CellRecord,
    CellStatus,
    read_batch_manifest,
)
from redrive.batch.run import BatchProgress, plan_cells, run_batch
from redrive.batch.spec import (
    LOOP_MODES,
    BatchSpec,
    LogItem,
    PipelineItem,
    expand_logs,
    load_batch_spec,
    make_pipeline_item,
    parse_seeds,
    pipeline_hash,
    unique_pipelines,
)

__all__ = [
    "BATCH_MANIFEST",
    "LOOP_MODES",
    "BatchManifest",
    "BatchProgress",
    "BatchSpec",
    "CellKey",
    "CellRecord",
    "CellRunner",
    "CellStatus",
    "CellTask",
    "ClosedLoopRunner",
    "LogItem",
    "PipelineItem",
    "expand_logs",
    "load_batch_spec",
    "make_pipeline_item",
    "parse_seeds",
    "pipeline_hash",
    "plan_cells",
    "read_batch_manifest",
    "run_batch",
    "run_cell",
    "unique_pipelines",
]
