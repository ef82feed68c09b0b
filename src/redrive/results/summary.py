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
    # the algorithm and status names as codes (numpy compares ints, not Python strings); a
    # dictionary encoding lists its values in order of first appearance
    algorithm = _encoded(steps.column("algorithm"))
    status_codes = _encoded(steps.column("status"))
    status = status_codes.indices.to_numpy(zero_copy_only=False)
    status_code = {name: k for k, name in enumerate(status_codes.dictionary.to_pylist())}
    codes = algorithm.indices.to_numpy(zero_copy_only=False)
    names = algorithm.dictionary.to_pylist()
    _, firsts = np.unique(codes, return_index=True)  # by code: the order of first appearance
    stage = steps.column("stage")
    role = steps.column("role")
    latency_ms = steps.column("latency_ns").to_numpy().astype(np.float64) / 1e6
    cpu_ms = steps.column("cpu_ns").to_numpy().astype(np.float64) / 1e6
    n_outputs = steps.column("n_outputs").to_numpy()
    skipped = status_code.get("skipped", -1)
    n_codes = len(status_code)
    rows: dict[str, list[Any]] = {name: [] for name in SUMMARY.names}
    for code, name in enumerate(names):
        i0 = int(firsts[code])
        sel = codes == code
        st = status[sel]
        ran = st != skipped
        lat = latency_ms[sel][ran]
        cpu = cpu_ms[sel][ran]
        rows["algorithm"].append(name)
        rows["stage"].append(stage[i0].as_py())
        rows["role"].append(role[i0].as_py())
        rows["frames"].append(int(st.size))
        per_status = np.bincount(st, minlength=n_codes).tolist()  # steps per status code
        for s in STATUSES:
            k = status_code.get(s)
            rows[s].append(0 if k is None else per_status[k])
        rows["outputs"].append(int(n_outputs[sel].sum()))
        has = lat.size > 0
        # both percentiles in one call: the same values as one call each, one sort
        p50, p95 = np.percentile(lat, (50, 95)).tolist() if has else (None, None)
        rows["latency_mean_ms"].append(float(lat.mean()) if has else None)
        rows["latency_p50_ms"].append(p50)
        rows["latency_p95_ms"].append(p95)
        rows["latency_max_ms"].append(float(lat.max()) if has else None)
        rows["cpu_mean_ms"].append(float(cpu.mean()) if has else None)
    return pa.Table.from_pydict(rows, schema=SUMMARY)


def _encoded(column: pa.ChunkedArray) -> pa.DictionaryArray:
    """``column`` dictionary-encoded in one chunk (values in order of first appearance)."""
    array = column.combine_chunks() if column.num_chunks != 1 else column.chunk(0)
    encoded = array.dictionary_encode()
    assert isinstance(encoded, pa.DictionaryArray)
    return encoded
