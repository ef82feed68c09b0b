"""The per-algorithm summary of a run's ``steps`` table."""

from __future__ import annotations

from typing import Any

import numpy as np
import pyarrow as pa

from redrive.results.records import STATUSES
from redrive.results.schema import SUMMARY

__all__ = ["summarize_steps"]


def summarize_steps(steps: pa.Table) -> pa.Table:
    """One row per algorithm, in order of first appearance in ``steps`` (the pipeline order).

    ``frames`` counts the frames the algorithm was scheduled on, ``ok`` … ``skipped`` the steps
    of each status, ``outputs`` the sum of ``n_outputs`` (objects, paths or commands).  Latency
    and CPU statistics are in milliseconds over the steps that ran (every status but
    ``skipped``); null when none ran.
    """
    algorithm = steps.column("algorithm").to_pylist()
    stage = steps.column("stage").to_pylist()
    role = steps.column("role").to_pylist()
    status = np.asarray(steps.column("status").to_pylist(), dtype=object)
    latency_ms = steps.column("latency_ns").to_numpy().astype(np.float64) / 1e6
    cpu_ms = steps.column("cpu_ns").to_numpy().astype(np.float64) / 1e6
    n_outputs = steps.column("n_outputs").to_numpy()
    names = np.asarray(algorithm, dtype=object)
    rows: dict[str, list[Any]] = {name: [] for name in SUMMARY.names}
    first: dict[str, int] = {}
    for i, name in enumerate(algorithm):
        first.setdefault(name, i)
    for name, i0 in first.items():
        sel = names == name
        st = status[sel]
        ran = st != "skipped"
        lat = latency_ms[sel][ran]
        cpu = cpu_ms[sel][ran]
        rows["algorithm"].append(name)
        rows["stage"].append(stage[i0])
        rows["role"].append(role[i0])
        rows["frames"].append(int(sel.sum()))
        for s in STATUSES:
            rows[s].append(int((st == s).sum()))
        rows["outputs"].append(int(n_outputs[sel].sum()))
        has = lat.size > 0
        rows["latency_mean_ms"].append(float(lat.mean()) if has else None)
        rows["latency_p50_ms"].append(float(np.percentile(lat, 50)) if has else None)
        rows["latency_p95_ms"].append(float(np.percentile(lat, 95)) if has else None)
        rows["latency_max_ms"].append(float(lat.max()) if has else None)
        rows["cpu_mean_ms"].append(float(cpu.mean()) if has else None)
    return pa.Table.from_pydict(rows, schema=SUMMARY)
