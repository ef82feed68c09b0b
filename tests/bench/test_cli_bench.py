"""``redrive bench read``: help and JSON output on a tiny log (no timings asserted); the synthetic
bag's command is benchmarks/tests/test_read_synth.py."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from benchmarks.synth_log import write_synthetic_bag
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
    assert "read-synth" in out  # where a synthetic bag to run it on comes from


def test_bench_without_benchmark_prints_help(capsys: pytest.CaptureFixture[str]) -> None:
    assert _run(["bench"]) == 2
    out = capsys.readouterr().out
    for name in ("read", "engine", "closed-loop", "transport"):
        assert name in out


def test_through_redrive_main(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from redrive.cli.main import main

    out = tmp_path / "m.bag"
    write_synthetic_bag(out, size_bytes=3 * 32 * 500, points=500)
    assert main(["bench", "read", "--repeat", "1", "--json", str(out)]) == 0
    assert json.loads(capsys.readouterr().out)["points"] > 0
    assert main(["bench", "read", str(tmp_path / "missing.bag")]) == 1
    assert "no such file" in capsys.readouterr().err
