"""``redrive bench read``: help, table and JSON output on a tiny log (no timings asserted)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from redrive.benchmarks import cli as bench


def _run(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="redrive")
    bench.register(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    status: int = args.func(args)
    return status


def test_help_has_an_example(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        _run(["bench", "read", "--help"])
    out = capsys.readouterr().out
    assert "redrive bench read drive.bag" in out
    assert "--synth" in out


def test_bench_without_benchmark_prints_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["bench"]) == 2
    assert "read" in capsys.readouterr().out


def test_synth_then_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.bag"
    argv = ["bench", "read", "--synth", "0.0001", "--points", "1000", "--repeat", "1", "--json"]
    assert _run([*argv, str(out)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["synthetic"]["points_per_message"] == 1000
    assert data["messages"] == data["synthetic"]["messages"] == 3
    assert data["points"] == 3000
    assert data["ratio"] > 0
    assert data["redrive"]["peak_rss_bytes"] > 0


def test_table_output(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "t.bag"
    argv = ["bench", "read", "--synth", "0.0001", "--points", "1000", "--repeat", "1"]
    assert _run([*argv, "--layout", "xyzi", "--compression", "lz4", str(out)]) == 0
    text = capsys.readouterr().out
    assert "raw (baseline)" in text
    assert "redrive (decode)" in text
    assert "ratio redrive/raw" in text


def test_through_redrive_main(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from redrive.cli.main import main

    out = tmp_path / "m.bag"
    argv = ["bench", "read", "--synth", "0.0001", "--points", "500", "--repeat", "1", "--json"]
    assert main([*argv, str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["points"] > 0
    assert main(["bench", "read", str(tmp_path / "missing.bag")]) == 1
    assert "no such file" in capsys.readouterr().err
