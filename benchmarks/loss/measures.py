"""The measures of one stream: ID difference, cumulative error, lost, late and latency."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from benchmarks.loss.streams import _NS, _SKIPPED, I64

__all__ = ["StreamLoss", "measure_stream"]


def _pct(values: npt.NDArray[np.float64], q: float) -> float:
    return float(np.percentile(values, q)) if values.size else math.nan


@dataclass(frozen=True, slots=True, kw_only=True)
class StreamLoss:
    """The measures of one stream in one configuration (see the module docstring).

    ``due = delivered + skipped_at_collector + unsent_at_end + lost_in_transport``. The series have
    one value per second of the run.
    """

    name: str
    rate_hz: float
    payload_bytes: int
    due: int
    delivered: int
    skipped_at_collector: int
    unsent_at_end: int
    lost_in_transport: int
    transport_dropped: int  # the reader's own count of keep-latest drops (redrive)
    corrupt: int
    late: int
    cumulative_error: int
    cumulative_error_last: int  # Σ of the snapshot at the last receipt of each second
    max_id_diff: int
    latency_p50_ms: float
    latency_p99_ms: float
    latency_max_ms: float
    collector_delay_p99_ms: float
    transport_p99_ms: float  # receipt − hand-over: the transport and the core's wake-up
    transport_max_ms: float
    id_diff: tuple[int, ...]
    id_diff_last: tuple[int, ...]
    lost_per_s: tuple[int, ...]

    @property
    def lost(self) -> int:
        return self.due - self.delivered

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        out: dict[str, Any] = {
            f: _finite(getattr(self, f))
            for f in self.__slots__
            if f not in ("id_diff", "id_diff_last", "lost_per_s")
        }
        out["lost"] = self.lost
        if series:
            out["series"] = {
                "id_diff": list(self.id_diff),
                "id_diff_last": list(self.id_diff_last),
                "lost": list(self.lost_per_s),
            }
        return out


def _finite(x: Any) -> Any:
    return None if isinstance(x, float) and not math.isfinite(x) else x


def measure_stream(
    name: str,
    *,
    rate_hz: float,
    payload_bytes: int,
    due_ns: I64,
    produced_ns: I64,
    recv_ns: I64,
    t0_ns: int,
    seconds: float,
    transport_dropped: int = 0,
    corrupt: int = 0,
) -> StreamLoss:
    """The measures of one stream from its three records, indexed by ID − 1: ``due_ns`` (sensor
    clock), ``produced_ns`` (hand-over time; 0 never handed over, −1 skipped at the collector) and
    ``recv_ns`` (receipt at the core; 0 never)."""
    delivered = recv_ns > 0
    ids = np.nonzero(delivered)[0] + 1
    recv = recv_ns[delivered]
    order = np.argsort(recv, kind="stable")
    ids, recv = ids[order], recv[order]
    high = np.maximum.accumulate(ids) if ids.size else ids  # R at each receipt
    newest = np.searchsorted(due_ns, recv, side="right")  # P at each receipt
    behind = newest - high
    n_sec = max(1, math.ceil(seconds - 1e-9))
    starts = t0_ns + np.arange(n_sec, dtype=np.int64) * _NS
    lo = np.searchsorted(recv, starts, side="left")
    hi = np.searchsorted(recv, starts + _NS, side="left")
    id_diff = np.zeros(n_sec, np.int64)
    id_last = np.zeros(n_sec, np.int64)
    for t in range(n_sec):
        if hi[t] > lo[t]:
            id_diff[t] = behind[lo[t] : hi[t]].max()
            id_last[t] = behind[hi[t] - 1]
        else:  # nothing received this second: P − R at its end
            got = int(high[hi[t] - 1]) if hi[t] > 0 else 0
            end_p = int(np.searchsorted(due_ns, starts[t] + _NS - 1, side="right"))
            id_diff[t] = id_last[t] = max(0, end_p - got)
    lost_sec = np.clip((due_ns[~delivered] - t0_ns) // _NS, 0, n_sec - 1)
    lost_per_s = np.bincount(lost_sec, minlength=n_sec)
    latency_ms = (recv - due_ns[ids - 1]) / 1e6
    sent = produced_ns > 0
    delay_ms = (produced_ns[sent] - due_ns[sent]) / 1e6
    transport_ms = (recv - produced_ns[ids - 1]) / 1e6
    return StreamLoss(
        name=name,
        rate_hz=rate_hz,
        payload_bytes=payload_bytes,
        due=int(due_ns.size),
        delivered=int(ids.size),
        skipped_at_collector=int(np.count_nonzero(produced_ns == _SKIPPED)),
        unsent_at_end=int(np.count_nonzero(produced_ns == 0)),
        lost_in_transport=int(np.count_nonzero(sent & ~delivered)),
        transport_dropped=transport_dropped,
        corrupt=corrupt,
        late=int(np.count_nonzero(newest > ids)),
        cumulative_error=int(id_diff.sum()),
        cumulative_error_last=int(id_last.sum()),
        max_id_diff=int(id_diff.max()),
        latency_p50_ms=_pct(latency_ms, 50),
        latency_p99_ms=_pct(latency_ms, 99),
        latency_max_ms=float(latency_ms.max()) if latency_ms.size else math.nan,
        collector_delay_p99_ms=_pct(delay_ms, 99),
        transport_p99_ms=_pct(transport_ms, 99),
        transport_max_ms=float(transport_ms.max()) if transport_ms.size else math.nan,
        id_diff=tuple(int(x) for x in id_diff),
        id_diff_last=tuple(int(x) for x in id_last),
        lost_per_s=tuple(int(x) for x in lost_per_s),
    )
