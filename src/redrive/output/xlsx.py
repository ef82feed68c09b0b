"""The one XLSX writer: openpyxl write-only workbooks of lazy sheets, cells made safe for Excel.

Every workbook redrive writes (``redrive export --format xlsx``, ``report.xlsx`` of a run and of
a batch) goes through :func:`write_xlsx`::

    write_xlsx(path, [Sheet(name="values", rows=lambda: iter([header, *rows]))])

Each cell passes :func:`excel_value`: text a spreadsheet would run as a formula gets a leading
``'`` (:func:`neutralize_cell`), text longer than Excel's cell limit is cut with a marker, NaN
and infinities become empty cells.  A sheet whose first row is its header has that row frozen
and filtered; a sheet longer than Excel's row limit continues on ``NAME (2)``, ``NAME (3)``, …
(each repeating the header).  The file is written atomically (:mod:`redrive.output.atomic`).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from redrive.output.atomic import atomic_path

if TYPE_CHECKING:
    import pyarrow as pa

__all__ = [
    "EXCEL_MAX_CHARS",
    "EXCEL_MAX_ROWS",
    "Sheet",
    "excel_value",
    "neutralize_cell",
    "table_rows",
    "write_xlsx",
]

#: rows of an Excel sheet, header included.
EXCEL_MAX_ROWS = 1_048_576
#: characters of an Excel cell.
EXCEL_MAX_CHARS = 32_767
#: what a cell's text starts with when a spreadsheet would read it as a formula.
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")
_TRUNCATED = "…[truncated]"
_BATCH_ROWS = 65_536


def neutralize_cell(text: str) -> str:
    """``text`` with a leading ``'`` when a spreadsheet would read it as a formula."""
    return "'" + text if text.startswith(FORMULA_START) else text


def excel_value(value: Any) -> Any:
    """A value Excel takes: formula-like text quoted, text cut at :data:`EXCEL_MAX_CHARS`
    (ending ``…[truncated]``), NaN and infinities empty (None)."""
    if isinstance(value, str):
        text = neutralize_cell(value)
        if len(text) > EXCEL_MAX_CHARS:
            text = text[: EXCEL_MAX_CHARS - len(_TRUNCATED)] + _TRUNCATED
        return text
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def table_rows(table: pa.Table, *, header: bool = True) -> Iterator[list[Any]]:
    """The rows of an Arrow table (its column names first when ``header``), converted a batch
    of rows at a time."""
    if header:
        yield list(table.column_names)
    for start in range(0, table.num_rows, _BATCH_ROWS):
        chunk = table.slice(start, _BATCH_ROWS)
        columns = [chunk.column(i).to_pylist() for i in range(chunk.num_columns)]
        yield from (list(row) for row in zip(*columns, strict=True))


@dataclass(frozen=True, slots=True, kw_only=True)
class Sheet:
    """One sheet: its name and its rows, made when the workbook is written.

    Attributes:
        name: the sheet's name (continuations add `` (2)``, `` (3)``, …).
        rows: called once; each row a sequence of cells.
        header: the first row is a header (frozen, filtered, repeated on continuations).
    """

    name: str
    rows: Callable[[], Iterable[Sequence[Any]]]
    header: bool = True


def write_xlsx(
    path: str | os.PathLike[str], sheets: Iterable[Sheet], *, max_rows: int = EXCEL_MAX_ROWS
) -> Path:
    """Write the workbook of ``sheets`` to ``path`` atomically; returns the path.

    ``max_rows`` is the rows of one sheet, header included (Excel's limit by default).
    """
    from openpyxl import Workbook
    from openpyxl.utils import get_column_letter

    wb = Workbook(write_only=True)
    for sheet in sheets:
        rows = iter(sheet.rows())
        head = [excel_value(x) for x in next(rows, [])] if sheet.header else None
        part = 0
        pending = True  # the first sheet is made even when there are no rows
        while pending:
            part += 1
            ws = wb.create_sheet(sheet.name if part == 1 else f"{sheet.name} ({part})")
            width = n = 0
            if head:
                ws.freeze_panes = "A2"
                ws.append(head)
                width, n = len(head), 1
            pending = False
            for row in rows:
                ws.append([excel_value(x) for x in row])
                width, n = max(width, len(row)), n + 1
                if n >= max_rows:
                    pending = True
                    break
            if head and width and n > 1:
                ws.auto_filter.ref = f"A1:{get_column_letter(width)}{n}"
            if pending:  # a full sheet: continue only if a row is left
                nxt = next(rows, None)
                if nxt is None:
                    break
                rows = _chain_one(nxt, rows)
    with atomic_path(path) as tmp:
        wb.save(tmp)
    return Path(path)


def _chain_one(first: Sequence[Any], rest: Iterator[Sequence[Any]]) -> Iterator[Sequence[Any]]:
    yield first
    yield from rest
