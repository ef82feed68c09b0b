"""Export a run's tables to merged Parquet files, CSV files or one Excel workbook.

CSV and Excel are opened by spreadsheet programs, which run a cell starting with ``=``, ``+``,
``-``, ``@``, tab or carriage return as a formula; every such string cell is written with a
leading ``'`` (OWASP "CSV injection").  Numbers stay numbers.  Excel cells hold at most 32,767
characters (longer strings are cut, ending in ``…[truncated]``) and sheets at most 1,048,576
rows (a longer table continues on sheets ``name (2)``, ``name (3)`` …).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from redrive.errors import ConfigError
from redrive.output.atomic import atomic_path
from redrive.output.xlsx import (
    EXCEL_MAX_CHARS,
    EXCEL_MAX_ROWS,
    Sheet,
    neutralize_cell,
    table_rows,
    write_xlsx,
)
from redrive.results.store import Run

__all__ = [
    "EXCEL_MAX_CHARS",
    "EXCEL_MAX_ROWS",
    "EXPORT_FORMATS",
    "export_run",
    "neutralize_cell",
]

logger = logging.getLogger(__name__)

EXPORT_FORMATS = ("parquet", "csv", "xlsx")
_FORMULA_RE = r"^[=+\-@\t\r]"  # the cells neutralize_cell quotes (FORMULA_START)


def _neutralize_strings(table: pa.Table) -> pa.Table:
    """Every string column of ``table`` with formula-like cells prefixed by ``'``."""
    for i, field in enumerate(table.schema):
        if pa.types.is_string(field.type) or pa.types.is_large_string(field.type):
            col = table.column(i)
            risky = pc.match_substring_regex(col, _FORMULA_RE)
            quoted = pc.binary_join_element_wise(pa.scalar("'", field.type), col, "")
            table = table.set_column(i, field, pc.if_else(risky, quoted, col))
    return table


def _write_parquet(path: Path, table: pa.Table) -> None:
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def _write_csv(path: Path, table: pa.Table) -> None:
    with atomic_path(path) as tmp:
        pacsv.write_csv(_neutralize_strings(table), tmp)


def export_run(run: Run, *, fmt: str, out: Path) -> list[Path]:
    """Write the tables of ``run`` that have rows into ``out`` (created); returns the files.

    ``parquet``: ``TABLE.parquet`` per table (all parts merged, sorted) and ``summary.parquet``;
    ``csv``: ``TABLE.csv`` per table and ``summary.csv``; ``xlsx``: one workbook ``RUN.xlsx``
    with a ``summary`` sheet (run facts and the per-algorithm summary) and a sheet per table.

    Raises:
        ConfigError: ``fmt`` is not one of :data:`EXPORT_FORMATS`.
    """
    if fmt not in EXPORT_FORMATS:
        msg = f"export format {fmt!r} is not one of {', '.join(EXPORT_FORMATS)}"
        raise ConfigError(msg)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = run.tables()
    written: list[Path] = []
    if fmt == "xlsx":
        path = out / f"{run.path.resolve().name or 'run'}.xlsx"
        _write_xlsx(path, run, names)
        written.append(path)
    else:
        write = _write_parquet if fmt == "parquet" else _write_csv
        for name in (*names, "summary"):
            path = out / f"{name}.{fmt}"
            write(path, run.summary() if name == "summary" else run.table(name))
            written.append(path)
    logger.info("exported %s as %s: %d files in %s", run.path, fmt, len(written), out)
    return written


# -- Excel ---------------------------------------------------------------------------------


def _flatten(prefix: str, value: Any) -> Iterator[tuple[str, Any]]:
    if isinstance(value, Mapping):
        for key, sub in value.items():
            yield from _flatten(f"{prefix}.{key}" if prefix else str(key), sub)
    elif isinstance(value, list | tuple):
        yield prefix, json.dumps(value, default=str)
    else:
        yield prefix, value


def _run_facts(run: Run) -> list[tuple[str, Any]]:
    facts: list[tuple[str, Any]] = [("run", str(run.path))]
    for key, value in _flatten("", run.manifest.to_json()):
        if key != "summary.algorithms":
            facts.append((key, value))
    return facts


def _write_xlsx(path: Path, run: Run, names: tuple[str, ...]) -> None:
    def summary() -> Iterator[list[Any]]:
        yield from ([key, value] for key, value in _run_facts(run))
        yield []
        yield from table_rows(run.summary())

    def table_sheet(name: str) -> Sheet:
        return Sheet(name=name, rows=lambda: table_rows(run.table(name)))

    sheets = [Sheet(name="summary", rows=summary, header=False), *map(table_sheet, names)]
    write_xlsx(path, sheets, max_rows=EXCEL_MAX_ROWS)
