"""A run's stored evaluation, one metric at a time: the on-disk format under ``RUN/metrics``.

Layout::

    RUN/metrics/index.json            {"format": 2, "metrics": {NAME: {"folder": ..., record}}}
    RUN/metrics/NAME.TOKEN/values.parquet     metric, metric_version, algorithm, key, value,
                                              unit, higher_is_better, subject, series,
                                              statistic — a row per named value
    RUN/metrics/NAME.TOKEN/per_frame.parquet  metric, algorithm, series, frame_index, value,
                                              subject
    RUN/metrics/NAME.TOKEN/curves.parquet     metric, algorithm, curve, point, x, y
    RUN/metrics/NAME.TOKEN/bookmarks.parquet  frame_index, stamp_ns, kind, metric, algorithm,
                                              detail, severity

``subject`` says whose motion or output a value scores: the algorithm's name, ``run`` (a
whole-run metric), or ``log`` — the logged ego of an open-loop run, the same whatever the
pipeline did (``redrive compare`` keeps such values out of the algorithms' comparison).
``series`` and ``statistic`` say how the value is made from a per-frame series (``max`` of
``max_lon_accel_mps2`` over the frames, ``mean`` …), empty when it is not; ``compare``
bootstraps that statistic for the value's confidence interval.  Tables stored before these
columns existed read with ``subject`` = the algorithm (or ``run``) and empty ``series`` and
``statistic``.

A metric's *record* (in the index) is what defines its numbers: name, version, role, unit,
higher_is_better, params, params_hash, plus ``evaluated`` (ISO time), ``algorithms`` (scored),
``skipped`` ([{algorithm, reason}]) and ``failed`` ([{algorithm, error}]).

Storing a metric writes its tables into a fresh hidden folder, then — under a lock — renames it
into place, replaces the index atomically (temp file + rename) and removes the folder it
superseded.  Every other metric
stays as it was; a crash at any point leaves an index that names complete folders only (a
half-written folder is an orphan, removed by the next store).  The engine, the evaluation and
the GUI all read the evaluation through this module.
"""

from __future__ import annotations

import fcntl
import json
import re
import shutil
import uuid
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from redrive.errors import ConfigError
from redrive.output.atomic import fsync_dir, sync_tree
from redrive.results.manifest import write_json_atomic

__all__ = [
    "BOOKMARKS",
    "CURVES",
    "INDEX_NAME",
    "METRICS_DIR",
    "PER_FRAME",
    "TABLE_SCHEMAS",
    "VALUES",
    "Evaluation",
    "read_evaluation",
    "store_metric",
    "stored_metric_names",
]

METRICS_DIR = "metrics"
INDEX_NAME = "index.json"
#: version of the metrics folder's layout (1: one set of tables for all metrics + manifest).
FORMAT = 2

_S, _F, _I = pa.string(), pa.float64(), pa.int64()
VALUES = pa.schema(
    [
        ("metric", _S),
        ("metric_version", _S),
        ("algorithm", _S),
        ("key", _S),
        ("value", _F),
        ("unit", _S),
        ("higher_is_better", pa.bool_()),
        ("subject", _S),
        ("series", _S),
        ("statistic", _S),
    ]
)
PER_FRAME = pa.schema(
    [
        ("metric", _S),
        ("algorithm", _S),
        ("series", _S),
        ("frame_index", _I),
        ("value", _F),
        ("subject", _S),
    ]
)
CURVES = pa.schema(
    [("metric", _S), ("algorithm", _S), ("curve", _S), ("point", _I), ("x", _F), ("y", _F)]
)
BOOKMARKS = pa.schema(
    [
        ("frame_index", _I),
        ("stamp_ns", _I),
        ("kind", _S),
        ("metric", _S),
        ("algorithm", _S),
        ("detail", _S),
        ("severity", _F),
    ]
)
#: table name → schema, in the order tables are read.
TABLE_SCHEMAS: Mapping[str, pa.Schema] = {
    "values": VALUES,
    "per_frame": PER_FRAME,
    "curves": CURVES,
    "bookmarks": BOOKMARKS,
}


@dataclass(frozen=True, slots=True, kw_only=True)
class Evaluation:
    """A run's stored evaluation: every stored metric's tables, concatenated, and their records.

    ``metrics`` holds one record per stored metric (see the module doc); ``evaluated`` is the
    time of the latest store.
    """

    values: pa.Table
    per_frame: pa.Table
    curves: pa.Table
    bookmarks: pa.Table
    metrics: tuple[Mapping[str, Any], ...]
    evaluated: str

    def value(self, metric: str, key: str, *, algorithm: str = "") -> float:
        """One stored value (NaN when absent)."""
        for row in self.values.to_pylist():
            if row["metric"] == metric and row["key"] == key and row["algorithm"] == algorithm:
                return float(row["value"])
        return float("nan")


def _folder_name(metric: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_.-]", "_", metric).strip(".") or "metric"
    return f"{safe}.{uuid.uuid4().hex[:12]}"


def _read_index(folder: Path) -> dict[str, Any]:
    path = folder / INDEX_NAME
    if not path.is_file():
        return {"format": FORMAT, "metrics": {}}
    try:
        index = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        msg = (
            f"{path}: cannot read the evaluation index ({err}); remove {folder} and run "
            "`redrive evaluate` again"
        )
        raise ConfigError(msg) from err
    if not isinstance(index, dict) or index.get("format") != FORMAT:
        msg = (
            f"{path}: evaluation layout {index.get('format') if isinstance(index, dict) else '?'}"
            f" is not the one this redrive reads ({FORMAT}); remove {folder} and run "
            "`redrive evaluate` again"
        )
        raise ConfigError(msg)
    if not isinstance(index.get("metrics"), dict):
        msg = f"{path}: damaged evaluation index (no metrics); run `redrive evaluate` again"
        raise ConfigError(msg)
    return index


def _check_old_layout(folder: Path) -> None:
    if not (folder / INDEX_NAME).is_file() and (folder / "values.parquet").is_file():
        msg = (
            f"{folder} holds an evaluation in the layout of an older redrive (one table for all "
            "metrics); run `redrive evaluate` on the run again to store it per metric"
        )
        raise ConfigError(msg)


@contextmanager
def _locked(folder: Path) -> Iterator[None]:
    """An exclusive lock on the metrics folder (two `redrive evaluate` of one run in parallel)."""
    with open(folder / ".lock", "w", encoding="utf-8") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def store_metric(
    run_dir: Path, *, record: Mapping[str, Any], tables: Mapping[str, pa.Table]
) -> Path:
    """Store one metric's results (``record["name"]`` names it), replacing only that metric's
    earlier results; returns the metrics folder.

    Args:
        run_dir: the run directory.
        record: the metric's record (see the module doc); JSON-serialisable.
        tables: ``values``, ``per_frame``, ``curves``, ``bookmarks`` with the schemas above
            (a missing table is stored empty).
    """
    folder = run_dir / METRICS_DIR
    folder.mkdir(exist_ok=True)
    _check_old_layout(folder)
    name = str(record["name"])
    sub = _folder_name(name)
    tmp = folder / f".{sub}.tmp"
    tmp.mkdir()
    for table_name, schema in TABLE_SCHEMAS.items():
        table = tables.get(table_name, schema.empty_table())
        pq.write_table(table.cast(schema), tmp / f"{table_name}.parquet")
    sync_tree(tmp)
    with _locked(folder):
        tmp.rename(folder / sub)
        fsync_dir(folder)
        index = _read_index(folder)
        index["metrics"][name] = {**record, "folder": sub}
        write_json_atomic(folder / INDEX_NAME, index)
        # The folder this one supersedes, and orphans of a store that died between its rename
        # and its index update (both happen under the lock, so no store is half-way now).
        live = {str(m.get("folder")) for m in index["metrics"].values()}
        for child in folder.iterdir():
            if child.is_dir() and child.name not in live and not child.name.startswith("."):
                shutil.rmtree(child, ignore_errors=True)
    return folder


def stored_metric_names(run_dir: Path) -> tuple[str, ...]:
    """The metrics stored for a run (empty when it has not been evaluated)."""
    folder = run_dir / METRICS_DIR
    if not (folder / INDEX_NAME).is_file():
        return ()
    return tuple(_read_index(folder)["metrics"])


#: columns added after the first stored layout: name → how an older table's rows fill it.
_ADDED = {"subject": "algorithm", "series": "", "statistic": ""}


def _read_table(path: Path, schema: pa.Schema) -> pa.Table:
    """A stored table in ``schema``; a table stored before the :data:`_ADDED` columns existed
    gets them (``subject``: the algorithm, or ``run`` for a whole-run metric)."""
    have = set(pq.read_schema(path).names)
    missing = [n for n in schema.names if n not in have]
    if not missing or any(n not in _ADDED for n in missing):
        return pq.read_table(path, schema=schema)
    table = pq.read_table(path, columns=[n for n in schema.names if n in have])
    for name in missing:
        fill = _ADDED[name]
        if fill == "algorithm":
            column = pa.array(
                [a or "run" for a in table.column("algorithm").to_pylist()], type=pa.string()
            )
        else:
            column = pa.array([fill] * table.num_rows, type=pa.string())
        table = table.append_column(name, column)
    return table.select(schema.names).cast(schema)


def read_evaluation(run_dir: Path, *, metrics: Sequence[str] | None = None) -> Evaluation:
    """Every stored metric of the run (or only ``metrics``), tables concatenated.

    Raises:
        ConfigError: the run has not been evaluated (says which command does it), its
            evaluation is of an older layout, or it is damaged.
    """
    folder = run_dir / METRICS_DIR
    _check_old_layout(folder)
    if not (folder / INDEX_NAME).is_file():
        msg = f"{run_dir} has not been evaluated; run `redrive evaluate {run_dir}` first"
        raise ConfigError(msg)
    index = _read_index(folder)
    records = [m for n, m in index["metrics"].items() if metrics is None or n in set(metrics)]
    parts: dict[str, list[pa.Table]] = {n: [] for n in TABLE_SCHEMAS}
    for record in records:
        sub = folder / str(record.get("folder"))
        for table_name, schema in TABLE_SCHEMAS.items():
            path = sub / f"{table_name}.parquet"
            try:
                parts[table_name].append(_read_table(path, schema))
            except (OSError, pa.ArrowException) as err:
                msg = (
                    f"{path}: cannot read the stored results of metric {record.get('name')!r} "
                    f"({err}); run `redrive evaluate {run_dir} --metric {record.get('name')}` "
                    "again"
                )
                raise ConfigError(msg) from err
    tables = {
        n: pa.concat_tables(p) if p else TABLE_SCHEMAS[n].empty_table() for n, p in parts.items()
    }
    marks = tables["bookmarks"]
    if marks.num_rows:
        marks = marks.sort_by([("severity", "descending"), ("frame_index", "ascending")])
    return Evaluation(
        values=tables["values"],
        per_frame=tables["per_frame"],
        curves=tables["curves"],
        bookmarks=marks,
        metrics=tuple({k: v for k, v in r.items() if k != "folder"} for r in records),
        evaluated=max((str(r.get("evaluated", "")) for r in records), default=""),
    )
