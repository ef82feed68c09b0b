"""redrive bench transport: tiny runs of every side deliver exactly what was sent (every byte
compared); the result types, targets and CLI. No timing is asserted.  (The peers' sides:
benchmarks/tests/test_transport_peers.py.)"""

from __future__ import annotations

import argparse
import dataclasses
import io
import json
import math

import pytest
from rich.console import Console

from redrive.benchmarks.cli.transport import _print_floors, add_transport_parser
from redrive.benchmarks.transport import (
    MIN_SIZE,
    SIDES,
    CellResult,
    MemcpyResult,
    RunResult,
    SideSpec,
    TransportBenchResult,
    bench_memcpy,
    bench_transport,
    check_targets,
    copy_floor_ms,
    parse_size,
    run_cell,
    side_available,
    target_spreads,
)
from redrive.errors import TransportError

SIZE = 64 << 10


def _needs(side: str) -> None:
    if not side_available(side):
        pytest.skip(f"{SIDES[side].module} is not installed ({SIDES[side].package})")


@pytest.mark.parametrize("side", list(SIDES))
def test_every_byte_arrives(side: str) -> None:
    _needs(side)
    r = run_cell(side, SIZE, seconds=0.15, verify=True)
    assert r.mode == "flat"
    assert r.sent > 0
    assert r.corrupt == 0  # every received payload equals the one sent, byte for byte
    assert 0 < r.received <= r.sent
    if not SIDES[side].lossy:
        assert r.received == r.sent
        assert r.out_of_order == 0
    if r.received >= 2:
        assert r.msgs_per_s > 0
        assert r.gb_per_s == pytest.approx(r.msgs_per_s * SIZE / 1e9)
    else:  # a loaded machine got one message through the 0.15 s window: a rate needs two
        assert math.isnan(r.msgs_per_s)
    assert 0 < r.latency_p50_ms <= r.latency_p99_ms <= r.latency_max_ms


def test_paced_run_measures_latency() -> None:
    r = run_cell("pipe-pickle", 2 * MIN_SIZE, seconds=0.2, paced_hz=50.0, verify=True)
    assert r.mode == "paced"
    assert 8 <= r.sent <= 12  # 50 Hz for 0.2 s
    assert r.received == r.sent
    assert r.corrupt == 0
    assert 0 < r.latency_p50_ms <= r.latency_p99_ms
    assert json.loads(json.dumps(r.to_json()))["lost"] == 0


def test_a_failing_side_reports_its_error() -> None:
    _needs("redrive-copy")
    with pytest.raises(TransportError, match="slots"):  # the writer refuses 2 slots
        run_cell("redrive-copy", SIZE, seconds=0.1, slots=2)
    with pytest.raises(TransportError, match="minimum"):
        run_cell("pipe-pickle", 100, seconds=0.1)


def test_missing_package_is_reported_not_run(monkeypatch: pytest.MonkeyPatch) -> None:
    ghost = SideSpec(
        name="ghost", label="ghost", module="redrive_no_such_module", package="ghost-pkg",
        publisher_first=False, lossy=False, in_place=False,
        make_sender=lambda cfg, shared: pytest.fail("must not run"),
        make_receiver=lambda cfg, shared, tally: pytest.fail("must not run"),
    )  # fmt: skip
    monkeypatch.setitem(SIDES, "ghost", ghost)  # type: ignore[arg-type]
    result = bench_transport([SIZE], sides=["ghost"], seconds=0.1, memcpy=False)
    (cell,) = result.cells
    assert cell.status == "not installed"
    assert cell.flat is None
    assert "ghost-pkg" in (cell.error or "")
    assert json.loads(json.dumps(result.to_json()))["cells"][0]["status"] == "not installed"


def test_memcpy_ceiling() -> None:
    (m,) = bench_memcpy([SIZE], seconds=0.1, pool_bytes=8 << 20)
    assert m.size_bytes == SIZE
    assert m.hot_gb_per_s > 0
    assert m.from_memory_gb_per_s > 0
    assert m.pool_bytes >= 8 << 20


def _run(side: str, size: int, gb_per_s: float, p99_ms: float = 1.0) -> CellResult:
    def run(mode: str) -> RunResult:
        return RunResult(
            mode=mode, seconds=1.0, sent=10, received=10, corrupt=0, out_of_order=0,
            msgs_per_s=gb_per_s * 1e9 / size, gb_per_s=gb_per_s, sent_per_s=10.0,
            latency_p50_ms=p99_ms / 2, latency_p99_ms=p99_ms, latency_max_ms=p99_ms,
        )  # fmt: skip

    return CellResult(side=side, size_bytes=size, status="ok", flat=run("flat"), paced=run("paced"))


def test_targets() -> None:
    mib = 1 << 20
    cells = (
        _run("redrive-inplace", mib, 12.0),
        _run("iceoryx2", mib, 10.0),
        _run("redrive-inplace", 4 * mib, 9.0, p99_ms=3.0),
        _run("iceoryx2", 4 * mib, 10.0),
        _run("redrive-copy", 4 * mib, 5.0, p99_ms=1.5),
        _run("pipe-pickle", 4 * mib, 0.4),
        _run("redrive-copy", 16 * mib, 4.0),
    )
    result = TransportBenchResult(
        sizes=(mib, 4 * mib, 16 * mib), seconds=1.0, paced_hz=100.0, slots=4, cells=cells,
        memcpy=(MemcpyResult(size_bytes=16 * mib, hot_gb_per_s=14.0, from_memory_gb_per_s=7.0,
                             pool_bytes=256 * mib),),
        targets=(),
    )  # fmt: skip
    by = {(t.name.split(" at ")[0], t.side, t.size_bytes): t for t in check_targets(result)}
    assert by["vs iceoryx2 in place", "redrive-inplace", mib].met is True
    assert by["vs iceoryx2 in place", "redrive-inplace", 4 * mib].ratio == pytest.approx(0.9)
    assert by["vs iceoryx2 in place", "redrive-inplace", 4 * mib].met is False
    assert by["vs pipe + pickle", "redrive-copy", 4 * mib].met is True  # 12.5x
    assert by["vs pipe + pickle", "redrive-inplace", 4 * mib].met is True  # 22.5x
    assert by["vs memcpy from memory", "redrive-copy", 16 * mib].met is True  # 4 / 7
    assert by["vs memcpy from memory", "redrive-inplace", 16 * mib].met is None  # did not run
    assert by["paced p99", "redrive-copy", 4 * mib].met is True
    assert by["paced p99", "redrive-inplace", 4 * mib].met is False
    assert by["paced p99 (issue 36)", "redrive-copy", 4 * mib].met is False  # 1.5 ms > 1 ms
    assert by["paced p99", "redrive-copy", 4 * mib].reference is None  # no memcpy at 4 MiB


def test_paced_targets_against_the_floor_of_their_copies() -> None:
    """A paced latency's reference is its copies at the same run's from-memory memcpy rate:
    copy-out two, in place one."""
    mib = 1 << 20
    n = 4 * mib

    def rep(p99_ms: float, from_memory_gb: float) -> TransportBenchResult:
        cells = (_run("redrive-copy", n, 5.0, p99_ms=p99_ms), _run("redrive-inplace", n, 9.0))
        mem = MemcpyResult(
            size_bytes=n, hot_gb_per_s=30.0, from_memory_gb_per_s=from_memory_gb, pool_bytes=n
        )
        result = TransportBenchResult(
            sizes=(n,), seconds=1.0, paced_hz=100.0, slots=4, cells=cells, memcpy=(mem,),
            targets=(),
        )  # fmt: skip
        return dataclasses.replace(result, targets=check_targets(result))

    one = rep(2.0, n / 1e6)  # 1 ms per copy
    by = {(t.name.split(" at ")[0], t.side): t for t in one.targets}
    assert copy_floor_ms(one, "redrive-copy", n) == pytest.approx(2.0)
    assert by["paced p99", "redrive-copy"].reference == pytest.approx(2.0)
    assert by["paced p99", "redrive-copy"].ratio == pytest.approx(1.0)
    assert by["paced p99", "redrive-inplace"].reference == pytest.approx(1.0)
    assert by["paced p99 (issue 36)", "redrive-copy"].met is False
    assert copy_floor_ms(one, "iceoryx2", n) is None
    spreads = target_spreads([one, rep(3.0, n / 2e6), rep(1.5, n / 1e6)])
    copy36 = next(t for t in spreads if t.name == "paced p99 (issue 36)")
    assert copy36.floors == pytest.approx((2.0, 4.0, 2.0))  # the second at half the rate
    assert copy36.floor_median == pytest.approx(2.0)
    assert copy36.floor_ratios == pytest.approx((1.0, 0.75, 0.75))
    assert next(t for t in spreads if t.name.startswith("vs")).floors == ()
    out = io.StringIO()
    _print_floors(Console(file=out, width=200), spreads, SIDES)
    lines = out.getvalue().splitlines()
    assert len(lines) == 3  # the paced targets: both sides at 2 ms, copy-out at 1 ms
    assert lines[-1] == (
        "paced p99 (issue 36), redrive copy-out: floor 2.00 ms (median), p99 ÷ floor "
        "0.75/0.75/1.00× (min/median/max) — the bound ≤ 1 ms is below the floor"
    )


def test_target_spreads_take_the_verdict_on_the_median() -> None:
    mib = 1 << 20

    def rep(redrive_gb: float, p99_ms: float) -> TransportBenchResult:
        cells = (
            _run("redrive-inplace", mib, redrive_gb),
            _run("iceoryx2", mib, 10.0),
            _run("redrive-inplace", 4 * mib, 10.0, p99_ms=p99_ms),
            _run("redrive-copy", 4 * mib, 10.0, p99_ms=p99_ms),
        )
        result = TransportBenchResult(
            sizes=(mib, 4 * mib), seconds=1.0, paced_hz=100.0, slots=4, cells=cells, memcpy=(),
            targets=(),
        )  # fmt: skip
        return dataclasses.replace(result, targets=check_targets(result))

    spreads = target_spreads([rep(12.0, 1.0), rep(8.0, 3.0), rep(11.0, 2.5)])
    by = {(t.name.split(" at ")[0], t.side, t.size_bytes): t for t in spreads}
    iox = by["vs iceoryx2 in place", "redrive-inplace", mib]
    assert iox.values == pytest.approx((1.2, 0.8, 1.1))
    assert (iox.min, iox.median, iox.max) == pytest.approx((0.8, 1.1, 1.2))
    assert iox.met is True  # one repetition below 1.0x does not decide it
    p99 = by["paced p99", "redrive-inplace", 4 * mib]
    assert (p99.min, p99.median, p99.max) == pytest.approx((1.0, 2.5, 3.0))
    assert p99.met is False  # ≤ 2 ms on the median
    assert by["vs pipe + pickle", "redrive-copy", 4 * mib].met is None  # never ran
    assert json.loads(json.dumps(iox.to_json()))["median"] == pytest.approx(1.1)


def test_parse_size() -> None:
    assert parse_size("64K") == 64 << 10
    assert parse_size("64KiB") == 64 << 10
    assert parse_size("4M") == 4 << 20
    assert parse_size("1.5M") == 3 << 19
    assert parse_size("4096") == 4096
    with pytest.raises(TransportError, match="not a message size"):
        parse_size("big")


def test_cli(capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    add_transport_parser(parser.add_subparsers())
    argv = ["transport", "--sizes", "16K", "--seconds", "0.1", "--sides", "pipe-pickle"]
    args = parser.parse_args([*argv, "--paced-hz", "50", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out)
    (cell,) = out["cells"]
    assert cell["status"] == "ok"
    assert cell["flat"]["corrupt"] == 0
    assert cell["paced"]["lost"] == 0
    assert out["memcpy"][0]["size_bytes"] == 16 << 10
    args = parser.parse_args([*argv, "--no-paced", "--no-memcpy"])
    assert args.func(args) == 0
    text = capsys.readouterr().out
    assert "pipe + pickle" in text
    assert "16 KiB" in text


def test_cli_repeat_reports_every_repetition(capsys: pytest.CaptureFixture[str]) -> None:
    parser = argparse.ArgumentParser()
    add_transport_parser(parser.add_subparsers())
    argv = ["transport", "--sizes", "16K", "--seconds", "0.1", "--sides", "pipe-pickle"]
    args = parser.parse_args([*argv, "--no-paced", "--no-memcpy", "--repeat", "2", "--json"])
    assert args.func(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert [r["cells"][0]["status"] for r in out["repetitions"]] == ["ok", "ok"]
    assert out["spread"] == []  # no target needs pipe + pickle alone


def test_cli_rejects_unknown_side() -> None:
    from redrive.errors import ConfigError

    parser = argparse.ArgumentParser()
    add_transport_parser(parser.add_subparsers())
    args = parser.parse_args(["transport", "--sides", "carrier-pigeon"])
    with pytest.raises(ConfigError, match="carrier-pigeon"):
        args.func(args)


def test_results_are_finite_or_null_in_json() -> None:
    r = RunResult(
        mode="flat", seconds=0.0, sent=0, received=0, corrupt=0, out_of_order=0,
        msgs_per_s=math.nan, gb_per_s=math.nan, sent_per_s=math.nan, latency_p50_ms=math.nan,
        latency_p99_ms=math.nan, latency_max_ms=math.nan,
    )  # fmt: skip
    out = json.loads(json.dumps(r.to_json(), allow_nan=False))
    assert out["gb_per_s"] is None
    assert out["lost"] == 0
