"""``python -m benchmarks read-synth``: a synthetic bag written, then ``redrive bench read`` of it,
as a table and as JSON with its "synthetic" section (no timings asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import main


def test_synth_then_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "s.bag"
    argv = ["read-synth", "0.0001", "--points", "1000", "--repeat", "1", "--json"]
    assert main([*argv, str(out)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["synthetic"]["points_per_message"] == 1000
    assert data["messages"] == data["synthetic"]["messages"] == 3
    assert data["points"] == 3000
    assert data["ratio"] > 0
    assert data["redrive"]["peak_rss_bytes"] > 0


def test_table_output(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "t.bag"
    argv = ["read-synth", "0.0001", "--points", "1000", "--repeat", "1"]
    assert main([*argv, "--layout", "xyzi", "--compression", "lz4", str(out)]) == 0
    text = capsys.readouterr().out
    assert "synthetic" in text
    assert "raw (baseline)" in text
    assert "redrive (decode)" in text
    assert "ratio redrive/raw" in text


def test_help_has_examples(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["read-synth", "--help"])
    assert "python -m benchmarks read-synth 2 /tmp/big.bag" in capsys.readouterr().out
