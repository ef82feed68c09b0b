"""python -m benchmarks loss: the measures on hand-made records, and a short real run of every chain.

The short run (3 s per configuration, ≈ 25 s in all) checks that the chains run, deliver, stop
every process and leave nothing in /dev/shm, and that the JSON / PNG / table are written and
consistent. It asserts no timing and not the 30-minute target (cumulative error 0): on a loaded
2-core VM a single descheduling of the collector or the core longer than a LiDAR period makes one
message late. What is robust and asserted: nothing corrupt, every due message accounted for, the
redrive chain at 1× loses (almost) nothing — keep-latest would need the core stalled for 8 LiDAR
periods (133 ms) to drop one — and the lossless chain loses nothing at all.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cli.loss import add_loss_parser
from benchmarks.loss import (
    STREAMS,
    LossBenchResult,
    bench_loss,
    due_times,
    measure_stream,
    table_markdown,
    wakeup_probe,
    write_outputs,
)
from redrive.errors import TransportError

T0 = 1_000_000_000_000


def _records(rate_hz: float, seconds: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    due = due_times(T0, rate_hz, seconds)
    return due, due + 1_000, due + 2_000_000  # handed over after 1 µs, received after 2 ms


def test_due_times() -> None:
    due = due_times(T0, 60.0, 2.0)
    assert due.size == 120
    assert due[0] == T0
    assert due[60] == T0 + 1_000_000_000
    assert due_times(T0, 15.0, 0.1).size == 2  # IDs due at 0 and 66.7 ms


def test_measures_of_one_stream() -> None:
    due, produced, recv = _records(10.0, 3.0)
    recv[4] = due[4] + 150_000_000  # ID 5 arrives after ID 6 was due ...
    recv[5] = due[4] + 151_000_000  # ... and ID 6 right behind it, in order, before ID 7 is due
    produced[11], recv[11] = -1, 0  # ID 12 overwritten in the collector's buffer
    recv[19] = 0  # ID 20 handed over, never received
    produced[29], recv[29] = 0, 0  # ID 30 still in the collector when the run stopped
    s = measure_stream(
        "x", rate_hz=10.0, payload_bytes=64, due_ns=due, produced_ns=produced, recv_ns=recv,
        t0_ns=T0, seconds=3.0,
    )  # fmt: skip
    assert (s.due, s.delivered, s.lost) == (30, 27, 3)
    assert (s.skipped_at_collector, s.unsent_at_end, s.lost_in_transport) == (1, 1, 1)
    assert s.late == 1
    assert s.id_diff == (1, 0, 0)  # second 0: at ID 5's receipt, ID 6 had been produced
    assert s.id_diff_last == (0, 0, 0)  # the last receipt of each second was on time
    assert s.cumulative_error == 1
    assert s.cumulative_error_last == 0
    assert s.max_id_diff == 1
    assert s.lost_per_s == (0, 2, 1)
    assert s.latency_p50_ms == pytest.approx(2.0)
    assert s.latency_max_ms == pytest.approx(150.0)


def test_a_second_without_receipts_counts_what_was_produced() -> None:
    due, produced, recv = _records(10.0, 3.0)
    recv[20:] = 0  # the core hears nothing in the last second
    s = measure_stream(
        "x", rate_hz=10.0, payload_bytes=64, due_ns=due, produced_ns=produced, recv_ns=recv,
        t0_ns=T0, seconds=3.0,
    )  # fmt: skip
    assert s.id_diff == (0, 0, 10)  # IDs 21–30 produced, the highest received is 20
    assert s.lost == s.lost_in_transport == 10
    assert s.late == 0


def test_nothing_received() -> None:
    due, produced, recv = _records(15.0, 2.0)
    s = measure_stream(
        "x", rate_hz=15.0, payload_bytes=64, due_ns=due, produced_ns=produced,
        recv_ns=np.zeros_like(recv), t0_ns=T0, seconds=2.0,
    )  # fmt: skip
    assert s.delivered == 0
    assert s.id_diff == (15, 30)
    assert np.isnan(s.latency_p50_ms)
    assert json.dumps(s.to_json())  # NaN becomes null


def test_text_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from benchmarks.cli.loss import _print_report
    from benchmarks.loss import ConfigResult

    due, produced, recv = _records(60.0, 2.0)
    stream = measure_stream(
        "lidar3d", rate_hz=60.0, payload_bytes=64, due_ns=due, produced_ns=produced,
        recv_ns=recv, t0_ns=T0, seconds=2.0,
    )  # fmt: skip
    result = LossBenchResult(
        seconds=2.0,
        configs=(
            ConfigResult(chain="redrive", rate_factor=1.0, seconds=2.0, streams=(stream,)),
            ConfigResult(chain="legacy", rate_factor=1.0, seconds=2.0, streams=(), error="boom"),
        ),
        machine={
            "cpu": "c",
            "cpus": "2",
            "system": "s",
            "python": "3",
            "load_average_at_start": "",
        },
    )
    paths = write_outputs(result, tmp_path)
    _print_report(result, paths)
    text = capsys.readouterr().out
    assert "meets" in text
    assert "failed" in text
    assert "failed: boom" in paths["table"].read_text()


def test_wakeup_probe() -> None:
    probe = wakeup_probe(0.05, period_s=0.005)
    assert probe["sleeps"] == 10
    assert 0 <= probe["overshoot_p50_ms"] <= probe["overshoot_max_ms"]
    assert 0 <= probe["fraction_over_one_period"] <= 1


def test_bad_arguments() -> None:
    with pytest.raises(TransportError, match="unknown chain"):
        bench_loss(seconds=1, chains=("zeromq",))
    with pytest.raises(TransportError, match="seconds > 0"):
        bench_loss(seconds=0)


def _leftovers() -> list[Path]:
    return sorted(Path("/dev/shm").glob(f"redrive.loss-{os.getpid()}-*"))


def _check_config(c: object, seconds: float) -> None:
    from benchmarks.loss import ConfigResult

    assert isinstance(c, ConfigResult)
    assert c.error is None, c.error
    assert [s.name for s in c.streams] == [st.name for st in STREAMS]
    for s, st in zip(c.streams, STREAMS, strict=True):
        assert s.rate_hz == st.rate_hz * c.rate_factor
        assert s.due == round(s.rate_hz * seconds)
        assert s.due == s.delivered + s.skipped_at_collector + s.unsent_at_end + s.lost_in_transport
        assert s.corrupt == 0
        assert s.delivered > 0
        assert len(s.id_diff) == len(s.id_diff_last) == len(s.lost_per_s) == seconds
        assert min(s.id_diff) >= 0
        assert s.cumulative_error == sum(s.id_diff)
        assert sum(s.lost_per_s) == s.lost
        assert s.latency_p50_ms > 0


@pytest.mark.slow  # ~25 s: both chains of the loss experiment; `make bench` runs it
def test_short_run_of_both_chains(tmp_path: Path) -> None:
    seconds = 3.0
    result = bench_loss(seconds=seconds, rate_factors=(1.0, 10.0), chains=("legacy", "redrive"))
    assert not multiprocessing.active_children()
    assert not _leftovers()
    assert [c.label for c in result.configs] == [
        "legacy 1×",
        "redrive 1×",
        "legacy 10×",
        "redrive 10×",
    ]
    for c in result.configs:
        _check_config(c, seconds)
    redrive_1x = result.configs[1]
    for s in redrive_1x.streams:
        assert s.skipped_at_collector == s.unsent_at_end == 0, s
        assert s.lost_in_transport <= s.due // 100, s
    paths = write_outputs(result, tmp_path / "out")
    data = json.loads(paths["json"].read_text())
    assert len(data["configurations"]) == 4
    assert data["wakeup_probe"]["sleeps"] > 0
    series = data["configurations"][1]["streams"][0]["series"]
    assert len(series["id_diff"]) == 3
    assert paths["png"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert paths["png"].stat().st_size > 10_000
    table = paths["table"].read_text()
    assert table == table_markdown(result)
    totals = [line for line in table.splitlines() if line.startswith("| **")]
    assert len(totals) == 4  # one total row per configuration
    assert "redrive 10×" in table


def test_cli_lossless(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    add_loss_parser(parser.add_subparsers())
    out = tmp_path / "loss"
    args = parser.parse_args(
        ["loss", "--seconds", "2", "--rates", "1", "--chains", "redrive-lossless",
         "--out", str(out), "--json"]
    )  # fmt: skip
    assert args.func(args) == 0
    data = json.loads(capsys.readouterr().out)
    (config,) = data["configurations"]
    assert config["chain"] == "redrive-lossless"
    assert config["lost"] == 0  # lossless: every message handed over is delivered
    assert "series" not in config["streams"][0]
    assert (out / "loss.png").exists()
    assert set(data["files"]) == {"json", "png", "table"}
    assert not _leftovers()
    with pytest.raises(SystemExit):
        parser.parse_args(["loss", "--rates", "0"])
    with pytest.raises(SystemExit):
        parser.parse_args(["loss", "--chains", "ros"])
