"""``python -m benchmarks export``: a run exported and its log copied once (no timings asserted); the
copy holds the log's messages as they are; the demo itself (synth + run) only in a slow test."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.cli import build_parser

pytest.importorskip("foxglove", reason="needs foxglove-sdk (pip install 'redrive[foxglove]')")


def _run(argv: list[str]) -> int:
    args = build_parser().parse_args(argv)
    status: int = args.func(args)
    return status


def test_copy_holds_the_logs_messages(tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from mcap.writer import Writer

    from benchmarks.export import copy_mcap

    src, dst = tmp_path / "in.mcap", tmp_path / "out.mcap"
    with src.open("wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        a = w.register_channel("/a", "cdr", schema, {"k": "v"})
        b = w.register_channel("/b", "json", 0)
        for i in range(20):
            w.add_message(a if i % 2 else b, log_time=i, data=bytes([i]) * i, publish_time=i)
        w.finish()
    assert copy_mcap(src, dst) == 20

    def read(path: Path) -> list[tuple[str, str, dict[str, str], int, bytes]]:
        with path.open("rb") as f:
            return [
                (c.topic, s.name if s else "", dict(c.metadata), m.log_time, m.data)
                for s, c, m in make_reader(f).iter_messages(log_time_order=True)
            ]

    assert read(dst) == read(src)


def test_run_exported_and_copied(
    short_run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["export", "--run", str(short_run), "--repeat", "1", "--workdir", str(tmp_path)]
    assert _run([*argv, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["copy_messages"] > 0
    # the export holds the log's messages (all but /tf) and the Foxglove channels on top
    assert data["export_messages"] > data["copy_messages"] * 0.8
    assert len(data["export_s"]) == len(data["copy_s"]) == 1
    assert data["log_span_s"] == pytest.approx(0.99, abs=0.02)
    assert data["ratio"] == pytest.approx(data["export_median_s"] / data["copy_median_s"])
    assert data["export_cpu_s"][0] > 0
    assert data["cpu_ratio"] == pytest.approx(data["export_cpu_s"][0] / data["copy_cpu_s"][0])
    assert not list(tmp_path.iterdir())  # the outputs were temporary


@pytest.mark.slow
def test_demo_made_exported_and_copied(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["export", "--duration", "0.3", "--repeat", "1", "--workdir", str(tmp_path)]
    assert _run([*argv, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["log_span_s"] == pytest.approx(0.29, abs=0.02)
    assert not list(tmp_path.iterdir())  # the demo and the outputs were temporary


def test_missing_run_log_says_so(tmp_path: Path) -> None:
    from benchmarks.export import bench_export
    from redrive.errors import ConfigError

    with pytest.raises(ConfigError, match="no such run directory"):
        bench_export(run=tmp_path / "nothing", repeats=1)
