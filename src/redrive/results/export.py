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
import math
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from redrive.errors import ConfigError
from redrive.output.atomic import atomic_path
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
#: rows of an Excel sheet, header included.
EXCEL_MAX_ROWS = 1_048_576
#: characters of an Excel cell.
EXCEL_MAX_CHARS = 32_767
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
_FORMULA_RE = r"^[=+\-@\t\r]"
_TRUNCATED = "…[truncated]"
_BATCH_ROWS = 65_536


def neutralize_cell(text: str) -> str:
    """``text`` with a leading ``'`` when a spreadsheet would read it as a formula."""
    return "'" + text if text.startswith(_FORMULA_START) else text


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


def _excel_text(text: str) -> str:
    text = neutralize_cell(text)
    if len(text) > EXCEL_MAX_CHARS:
        text = text[: EXCEL_MAX_CHARS - len(_TRUNCATED)] + _TRUNCATED
    return text


def _excel_value(value: Any) -> Any:
    if isinstance(value, str):
        return _excel_text(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None  # Excel has no NaN or infinity
    return value


def _excel_column(col: pa.ChunkedArray | pa.Array) -> list[Any]:
    values: list[Any] = col.to_pylist()
    if pa.types.is_string(col.type) or pa.types.is_large_string(col.type):
        return [None if v is None else _excel_text(v) for v in values]
    if pa.types.is_floating(col.type):
        return [v if v is None or math.isfinite(v) else None for v in values]
    return values


def _table_rows(table: pa.Table) -> Iterator[tuple[Any, ...]]:
    for start in range(0, table.num_rows, _BATCH_ROWS):
        chunk = table.slice(start, _BATCH_ROWS)
        columns = [_excel_column(chunk.column(i)) for i in range(chunk.num_columns)]
        yield from zip(*columns, strict=True)


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
    from openpyxl import Workbook

    wb = Workbook(write_only=True)
    ws = wb.create_sheet("summary")
    for key, value in _run_facts(run):
        ws.append([_excel_text(key), _excel_value(value)])
    ws.append([])
    summary = run.summary()
    ws.append([_excel_text(n) for n in summary.column_names])
    for row in _table_rows(summary):
        ws.append(list(row))
    per_sheet = EXCEL_MAX_ROWS - 1
    for name in names:
        table = run.table(name)
        header = [_excel_text(n) for n in table.column_names]
        sheets = max(1, math.ceil(table.num_rows / per_sheet))
        for k in range(sheets):
            sheet = wb.create_sheet(name if k == 0 else f"{name} ({k + 1})")
            sheet.freeze_panes = "A2"
            sheet.append(header)
            for row in _table_rows(table.slice(k * per_sheet, per_sheet)):
                sheet.append(list(row))
    with atomic_path(path) as tmp:
        wb.save(tmp)
