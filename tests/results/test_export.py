"""Exports: merged Parquet, CSV (numbers round-trip), Excel (summary, values, formula injection)."""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path
from typing import Any

import openpyxl
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from redrive.cli import export as export_cli
from redrive.errors import ConfigError
from redrive.results import RunWriter, export_run, open_run
from redrive.results import export as export_mod
from tests.results._records import EVIL, SETUP, T0_NS, frame

_LONG = "Traceback:\n" + "x" * 40_000


def _row(header: tuple[Any, ...], row: tuple[Any, ...]) -> dict[Any, Any]:
    """A sheet row by column name (read-only openpyxl drops trailing empty cells)."""
    return dict(itertools.zip_longest(header, row))


@pytest.fixture
def run_dir(tmp_path: Path) -> Path:
    path = tmp_path / "urban_run"
    with RunWriter(path, setup=SETUP, flush_every=3) as writer:
        for i in range(7):
            writer.write_frame(frame(i, long_traceback=_LONG if i == 4 else ""))
    return path


def test_parquet_export_merges_parts(run_dir: Path, tmp_path: Path) -> None:
    run = open_run(run_dir)
    files = export_run(run, fmt="parquet", out=tmp_path / "pq")
    assert [f.name for f in files] == [f"{n}.parquet" for n in (*run.tables(), "summary")]
    assert "resources" not in run.tables()
    for name in run.tables():
        assert pq.read_table(tmp_path / "pq" / f"{name}.parquet").equals(run.table(name))
    assert pq.read_table(tmp_path / "pq" / "summary.parquet").equals(run.summary())


def test_csv_export_round_trips_numbers(run_dir: Path, tmp_path: Path) -> None:
    run = open_run(run_dir)
    files = export_run(run, fmt="csv", out=tmp_path / "csv")
    assert tmp_path / "csv" / "summary.csv" in files
    for name in ("detections", "ego", "paths", "frames"):
        table = run.table(name)
        back = pacsv.read_csv(tmp_path / "csv" / f"{name}.csv")
        assert back.column_names == table.column_names
        for col in table.column_names:
            if table.schema.field(col).type in ("double", "int64"):
                assert back.column(col).to_pylist() == table.column(col).to_pylist(), (name, col)
    ego = pacsv.read_csv(tmp_path / "csv" / "ego.csv")
    assert ego.column("stamp_ns").to_pylist()[0] == T0_NS  # int64 ns survive exactly
    steps = pacsv.read_csv(tmp_path / "csv" / "steps.csv").to_pylist()
    errors = [r for r in steps if r["status"] == "error"]
    assert errors[0]["error_message"] == "'" + EVIL
    assert len(errors[2]["traceback"]) == len(_LONG)  # CSV has no cell limit
    # strings that look like formulas only at the start are left alone
    assert errors[0]["error_type"] == "ZeroDivisionError"
    summary = pacsv.read_csv(tmp_path / "csv" / "summary.csv")
    assert summary.column("algorithm").to_pylist() == ["det", "bad_det", "planner", "ctrl"]


def test_xlsx_export(run_dir: Path, tmp_path: Path) -> None:
    run = open_run(run_dir)
    (path,) = export_run(run, fmt="xlsx", out=tmp_path / "x")
    assert path.name == "urban_run.xlsx"
    wb = openpyxl.load_workbook(path, read_only=True)
    assert wb.sheetnames == ["summary", *run.tables()]
    facts = {
        r[0]: _row(("k", "v"), r[:2])["v"] for r in wb["summary"].iter_rows(values_only=True) if r
    }
    assert facts["status"] == "complete"
    assert facts["log.sha256"] == "abc"
    assert facts["pipeline.stop_frame"] is None
    assert facts["algorithms"].startswith('[{"name": "det"')
    assert facts["frames_done"] == 7
    assert facts["summary.late_frames"] == 1
    rows = list(wb["summary"].iter_rows(values_only=True))
    header_at = next(i for i, r in enumerate(rows) if r and r[0] == "algorithm")
    assert rows[header_at + 1][:4] == ("det", "perception", "perception", 7)

    det_rows = list(wb["detections"].iter_rows(values_only=True))
    header = det_rows[0]
    first = _row(header, det_rows[1])
    want = run.table("detections").to_pylist()[0]
    # numbers stay numbers, None stays empty; Excel (and openpyxl, "%.16g") keep 16 digits, so
    # int64 ns stamps near 1.7e18 come back within ~100 ns
    assert first.keys() == want.keys()
    for key, value in want.items():
        if isinstance(value, str) or value is None:
            assert first[key] == value, key
        else:
            assert first[key] == pytest.approx(value, rel=1e-15), key
    assert isinstance(first["x"], float)
    assert isinstance(first["frame_index"], int)
    assert first["stamp_ns"] == pytest.approx(T0_NS + 100_000_000, abs=1000)
    by_id = {r[header.index("object_id")]: _row(header, r) for r in det_rows[1:]}
    assert by_id[200]["bbox_x"] == 0.0
    assert by_id[201]["bbox_x"] is None

    step_rows = list(wb["steps"].iter_rows(values_only=True))
    cols = step_rows[0]
    errors = [_row(cols, r) for r in step_rows[1:] if r[cols.index("status")] == "error"]
    assert errors[0]["error_message"] == '\'=HYPERLINK("http://x")'
    long_tb = errors[2]["traceback"]
    assert len(long_tb) == export_mod.EXCEL_MAX_CHARS
    assert long_tb.endswith("…[truncated]")
    assert isinstance(_row(cols, step_rows[1])["latency_ns"], int)
    wb.close()


def test_xlsx_splits_long_tables(
    run_dir: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(export_mod, "EXCEL_MAX_ROWS", 5)  # header + 4 rows per sheet
    run = open_run(run_dir)
    (path,) = export_run(run, fmt="xlsx", out=tmp_path / "x")
    wb = openpyxl.load_workbook(path, read_only=True)
    n = run.table("steps").num_rows  # 28 → 7 sheets
    names = [s for s in wb.sheetnames if s.startswith("steps")]
    assert names == ["steps", *(f"steps ({k})" for k in range(2, 8))]
    got = [r for s in names for r in list(wb[s].iter_rows(values_only=True))[1:]]
    assert len(got) == n
    assert [r[0] for r in got] == run.table("steps").column("frame_index").to_pylist()
    wb.close()


def test_neutralize_cell() -> None:
    for bad in ("=1+1", "+1", "-1", "@SUM(A1)", "\tx", "\rx"):
        assert export_mod.neutralize_cell(bad) == "'" + bad
    assert export_mod.neutralize_cell("a=1") == "a=1"


def test_unknown_format(run_dir: Path, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="'ods' is not one of"):
        export_run(open_run(run_dir), fmt="ods", out=tmp_path)


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="redrive")
    export_cli.register(parser.add_subparsers(dest="command"))
    return parser


def test_cli_register(run_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = _parser().parse_args(["export", str(run_dir), "--format", "csv"])
    assert args.func(args) == 0
    printed = capsys.readouterr().out.split()
    assert str(run_dir / "export" / "steps.csv") in printed
    assert (run_dir / "export" / "summary.csv").is_file()
    args = _parser().parse_args(
        ["export", str(run_dir), "--format", "xlsx", "-o", str(tmp_path / "o")]
    )
    assert args.func(args) == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "o" / "urban_run.xlsx")
    with pytest.raises(SystemExit):
        _parser().parse_args(["export", str(run_dir), "--format", "ods"])
    # the run directory is still a run after an export into it
    assert open_run(run_dir).table("frames").num_rows == 7


def test_cli_main_when_wired(run_dir: Path, tmp_path: Path) -> None:
    from redrive.cli import main as cli_main

    if "export" not in cli_main._COMMANDS:
        pytest.skip("`export` is not wired into redrive.cli.main yet")
    assert cli_main.main(["export", str(run_dir), "--format", "parquet", "-o", str(tmp_path)]) == 0
    assert (tmp_path / "frames.parquet").is_file()
    assert cli_main.main(["export", str(tmp_path / "nope"), "--format", "csv"]) == 1


def test_excel_cells_without_nan() -> None:
    import pyarrow as pa

    from redrive.output.xlsx import excel_value

    col = pa.array([1.5, float("nan"), None, float("-inf")])
    assert [excel_value(v) for v in col.to_pylist()] == [1.5, None, None, None]
    strings = pa.array(["-x", None, "ok"]).to_pylist()
    assert [excel_value(v) for v in strings] == ["'-x", None, "ok"]
