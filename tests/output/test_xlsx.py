"""The one XLSX writer: safe cells, frozen and filtered headers, long sheets continued."""

from __future__ import annotations

from pathlib import Path

import openpyxl

from redrive.output.xlsx import EXCEL_MAX_CHARS, Sheet, excel_value, write_xlsx


def test_cells_are_safe_for_excel() -> None:
    assert excel_value("=1+1") == "'=1+1"
    assert excel_value("a=1") == "a=1"
    assert excel_value(float("nan")) is None
    assert excel_value(2) == 2
    long = excel_value("x" * (EXCEL_MAX_CHARS + 5))
    assert len(long) == EXCEL_MAX_CHARS
    assert long.endswith("…[truncated]")


def test_sheets_headers_and_continuations(tmp_path: Path) -> None:
    rows = [["n", "text"], *([i, f"={i}"] for i in range(7))]
    path = write_xlsx(
        tmp_path / "book.xlsx",
        [
            Sheet(name="facts", rows=lambda: iter([["a", 1], [], ["b", 2]]), header=False),
            Sheet(name="values", rows=lambda: iter(rows)),
            Sheet(name="empty", rows=lambda: iter([])),
        ],
        max_rows=4,  # the header and three rows per sheet
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["book.xlsx"]
    wb = openpyxl.load_workbook(path)
    assert wb.sheetnames == ["facts", "values", "values (2)", "values (3)", "empty"]
    assert wb["values"].freeze_panes == "A2"
    assert wb["values"].auto_filter.ref == "A1:B4"
    assert wb["facts"].freeze_panes is None
    got = [
        r for s in ("values", "values (2)", "values (3)") for r in wb[s].iter_rows(values_only=True)
    ]
    assert got[0] == ("n", "text")
    body = [r for r in got if r != ("n", "text")]
    assert body == [(i, f"'={i}") for i in range(7)]
    assert list(wb["empty"].iter_rows(values_only=True)) == []
