"""The per-algorithm summary of a steps table, against the same figures counted in plain Python."""

from __future__ import annotations

import random
import statistics

import numpy as np
import pyarrow as pa
import pytest

from redrive.results.schema import SCHEMAS
from redrive.results.summary import summarize_steps


def _steps(seed: int, n: int) -> pa.Table:
    rng = random.Random(seed)
    rows: dict[str, list[object]] = {name: [] for name in SCHEMAS["steps"].names}
    for i in range(n):
        name = rng.choice(["planner", "det", "ctrl"])
        rows["frame_index"].append(i)
        rows["stamp_ns"].append(i * 100)
        rows["algorithm"].append(name)
        rows["stage"].append("stage-" + name)
        rows["role"].append("perception")
        rows["status"].append(rng.choice(["ok", "ok", "error", "skipped", "timeout"]))
        rows["latency_ns"].append(rng.randint(0, 10**8))
        rows["cpu_ns"].append(rng.randint(0, 10**8))
        rows["n_outputs"].append(rng.randint(0, 9))
        for key in ("error_type", "error_message", "traceback"):
            rows[key].append("")
    rows["algorithm"].append("never-ran")  # only skipped steps: no latency figures
    rows["status"].append("skipped")
    for key, value in (("frame_index", n), ("stamp_ns", n), ("latency_ns", 0), ("cpu_ns", 0),
                       ("n_outputs", 0), ("stage", "s"), ("role", "control"), ("error_type", ""),
                       ("error_message", ""), ("traceback", "")):  # fmt: skip
        rows[key].append(value)
    table = pa.Table.from_pydict(rows, schema=SCHEMAS["steps"])
    return pa.concat_tables([table.slice(0, n // 3), table.slice(n // 3)])  # two chunks


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_summary_counts_and_latencies(seed: int) -> None:
    steps = _steps(seed, 40)
    got = {row["algorithm"]: row for row in summarize_steps(steps).to_pylist()}
    rows = steps.to_pylist()
    order = list(dict.fromkeys(r["algorithm"] for r in rows))
    assert list(got) == order  # first appearance
    for name in order:
        mine = [r for r in rows if r["algorithm"] == name]
        ran = [r for r in mine if r["status"] != "skipped"]
        row = got[name]
        assert (row["stage"], row["role"], row["frames"]) == (
            mine[0]["stage"],
            mine[0]["role"],
            len(mine),
        )
        for status in ("ok", "error", "timeout", "skipped"):
            assert row[status] == sum(r["status"] == status for r in mine)
        assert row["outputs"] == sum(r["n_outputs"] for r in mine)
        if not ran:
            assert row["latency_mean_ms"] is None
            assert row["cpu_mean_ms"] is None
            continue
        lat = [r["latency_ns"] / 1e6 for r in ran]
        assert row["latency_mean_ms"] == pytest.approx(statistics.fmean(lat))
        assert row["latency_p50_ms"] == pytest.approx(float(np.percentile(lat, 50)))
        assert row["latency_p95_ms"] == pytest.approx(float(np.percentile(lat, 95)))
        assert row["latency_max_ms"] == max(lat)
        assert row["cpu_mean_ms"] == pytest.approx(statistics.fmean(r["cpu_ns"] / 1e6 for r in ran))


def test_an_empty_steps_table_has_an_empty_summary() -> None:
    assert summarize_steps(SCHEMAS["steps"].empty_table()).num_rows == 0
