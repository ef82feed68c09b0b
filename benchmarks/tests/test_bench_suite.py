"""`python -m benchmarks all`: each benchmark's outcome becomes a row of one markdown table (run here
with a stand-in for the child processes: the benchmarks themselves are not run)."""

from __future__ import annotations

import json
import subprocess
from typing import Any

import pytest

from benchmarks.cli import main
from benchmarks.suite import SUITE, SuiteEntry, run_suite, summary_markdown

_ENGINE_JSON = {
    "engine": {
        "frames": 10,
        "spread": [
            {"name": "pipelined ÷ bare loop", "bound": 1.5, "at_most": False,
             "values": [1.2, 1.6, 1.7], "min": 1.2, "median": 1.6, "max": 1.7, "met": True},
        ],
    }
}  # fmt: skip


_EVAL_JSON = {
    "speedup": 41.5,
    "target_ratio": 10,
    "log_duration_s": 0.3,
    "vectorised": {"frames_per_s": 9e4},
}


def _fake(outcomes: dict[str, Any]) -> Any:
    def run(cmd: list[str], **kwargs: Any) -> subprocess.CompletedProcess[str]:
        name = cmd[cmd.index("bench" if "redrive" in cmd else "benchmarks") + 1]
        outcome = outcomes[name]
        if outcome == "timeout":
            raise subprocess.TimeoutExpired(cmd, kwargs["timeout"])
        code, stdout, stderr = outcome
        return subprocess.CompletedProcess(cmd, code, stdout, stderr)

    return run


def test_rows_say_what_each_benchmark_did() -> None:
    entries = [
        SuiteEntry(name="engine", args=("engine",), why="small", timeout_s=10, redrive=True),
        SuiteEntry(name="eval", args=("eval",), why="tiny", timeout_s=10),
        SuiteEntry(name="lidar", args=("lidar",), why="x", timeout_s=10),
        SuiteEntry(name="gui", args=("gui",), why="y", timeout_s=10),
        SuiteEntry(name="loss", args=("loss", "--out", "{tmp}/l"), why="z", timeout_s=1000),
    ]
    outcomes = {
        "engine": (0, json.dumps(_ENGINE_JSON), ""),
        "eval": (0, json.dumps(_EVAL_JSON), ""),
        "lidar": (1, "", "Traceback ...\nredrive: open3d is not installed; pip install open3d"),
        "gui": "timeout",
    }
    rows = run_suite(entries, budget_s=100.0, runner=_fake(outcomes))
    by = {r.entry.name: r for r in rows}
    assert by["engine"].status == "ok"
    assert by["engine"].figures == (
        "pipelined ÷ bare loop: 1.2/1.6/1.7 (min/median/max) ≥ 1.5 meets",
    )
    assert by["eval"].figures == ("speedup 41.5", "vectorised.frames_per_s 90,000")
    assert by["lidar"].status == (
        "failed (exit code 1): redrive: open3d is not installed; pip install open3d"
    )
    assert by["gui"].status == "timeout"
    assert by["loss"].status.startswith("skipped (its limit of 1000 s")
    text = summary_markdown(rows, loadavg="1.0 2.0 3.0", host="box")
    lines = text.splitlines()
    assert "| benchmark | configuration | status | s | figures |" in lines
    assert len([ln for ln in lines if ln.startswith("| ")]) == 1 + len(entries)
    assert "load average before: 1.0 2.0 3.0" in text
    assert "`redrive bench engine --json` — small" in text


def test_every_suite_entry_parses_with_a_unique_name() -> None:
    from benchmarks.cli import build_parser as benchmarks_parser
    from redrive.cli.main import build_parser

    redrive, benchmarks = build_parser(), benchmarks_parser()
    for entry in SUITE:
        argv = [a.replace("{tmp}", "/t") for a in entry.args]
        if entry.redrive:
            args = redrive.parse_args(["bench", *argv])
        else:
            args = benchmarks.parse_args(argv)
        assert callable(args.func), entry.name
    names = [e.name for e in SUITE]
    assert len(set(names)) == len(names)


def test_cli_rejects_an_unknown_benchmark(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["all", "--only", "engine,nope"]) != 0
    assert "--only: unknown nope" in capsys.readouterr().err
