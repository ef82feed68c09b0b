"""`python -m benchmarks batch` runs tiny batches and reports consistent numbers (no timing asserts:
speed targets are met in the benchmark, BENCHMARKS.md)."""

from __future__ import annotations

import json

import pytest

from benchmarks.batch import bench_batch
from benchmarks.cli import main
from redrive.errors import ConfigError


def test_bench_batch_local_numbers_add_up() -> None:
    r = bench_batch(logs=2, log_duration_s=0.5, empty_cells=2, ray=False)
    assert (r.logs, r.empty_cells, r.repeats) == (2, 2, 1)
    assert r.ray2_s is None
    assert r.ray_ratio is None
    assert r.ray_cell_overhead_s is None
    assert r.local1_s > 0
    assert r.local2_s > 0
    assert r.scaling == pytest.approx(r.local1_s / r.local2_s)
    # the cost beyond the run is part of the wall per cell
    assert r.local_empty_cell_s > 0
    assert r.local_cell_overhead_s < r.local_empty_cell_s
    assert set(r.passes) == {"local1", "local2", "local_empty"}
    out = r.to_json()
    assert out["targets"] == {"scaling": 1.7, "ray_ratio": 0.9, "ray_cell_overhead_s": 0.5}
    assert len(out["load_before"]) == 3


def test_bench_batch_refuses_no_logs() -> None:
    with pytest.raises(ConfigError, match="must be >= 1"):
        bench_batch(logs=0, ray=False)


def test_bench_batch_cli_json(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["batch", "--logs", "1", "--duration", "0.3", "--empty-cells", "1"]
    assert main([*argv, "--no-ray", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["logs"] == 1
    assert out["ray2_s"] is None
    assert out["pipeline"] == ["cluster-detector", "idm-planner", "pure-pursuit-pid"]


def test_bench_fleet_slope_and_rss() -> None:
    from benchmarks.fleet import _slope, rss_bytes

    assert rss_bytes() > 10_000_000  # this process: Python, numpy, pyarrow
    assert _slope([(0, 1.0), (100, 3.0), (200, 5.0)]) == pytest.approx(2.0)
    assert _slope([(5, 7.0)]) == 0.0


@pytest.mark.slow  # four cells, each a process: ~20 s on a loaded 2-core machine
def test_bench_fleet_samples_the_driver_at_every_finished_cell() -> None:
    from benchmarks.fleet import bench_fleet

    r = bench_fleet(cells=4, log_duration_s=0.2, executor="local", workers=1)
    assert r.failed == 0
    assert [n for n, _ in r.samples] == [1, 2, 3, 4]
    assert r.rss_mb_max == max(mb for _, mb in r.samples)
    assert r.rss_mb_end == r.samples[-1][1]
