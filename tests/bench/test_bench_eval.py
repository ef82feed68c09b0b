"""``redrive bench eval``: the CPU seconds of each metric on a run (no timings asserted)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from redrive.cli.main import main

PDM = "redrive.evaluation.closedloop.pdm"


def test_bench_eval_json(demo_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["bench", "eval", str(demo_run), "--json"]
    for cls in ("NavsimPdms", "NavsimEpdms"):
        args += ["--metric", f"{PDM}:{cls}"]
    assert main(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [(m["metric"], m["algorithm"], m["outcome"]) for m in out["metrics"]] == [
        ("navsim_pdms", "planner", "scored"),
        ("navsim_epdms", "planner", "scored"),
    ]
    assert out["load_cpu_s"] > 0
    assert out["metrics_cpu_s"] == pytest.approx(sum(m["cpu_s"] for m in out["metrics"]))
    stored = [p.name for p in (demo_run / "metrics").glob("navsim_*")]
    assert stored == []  # nothing stored


def test_bench_eval_report_and_help(demo_run: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "eval", str(demo_run), "--metric", f"{PDM}:NavsimPdms"]) == 0
    out = capsys.readouterr().out
    assert "navsim_pdms (planner):" in out
    assert "metrics in all:" in out
    with pytest.raises(SystemExit):
        main(["bench", "eval", "--help"])
    assert "redrive bench eval RUN" in capsys.readouterr().out
