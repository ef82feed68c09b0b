"""The results of a run: one :class:`ConfigResult` per chain and rate factor, and all of them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from benchmarks.loss.measures import StreamLoss
from benchmarks.loss.streams import DRAIN_S, QUEUE_DEPTH, SENSOR_BUFFER_S, SLOTS, STREAMS

__all__ = ["ConfigResult", "LossBenchResult"]


@dataclass(frozen=True, slots=True, kw_only=True)
class ConfigResult:
    """One chain at one rate factor; ``error`` says why it did not complete (then no streams)."""

    chain: str
    rate_factor: float
    seconds: float
    streams: tuple[StreamLoss, ...]
    error: str | None = None

    @property
    def label(self) -> str:
        return f"{self.chain} {self.rate_factor:g}×"

    @property
    def cumulative_error(self) -> int:
        return sum(s.cumulative_error for s in self.streams)

    @property
    def lost(self) -> int:
        return sum(s.lost for s in self.streams)

    @property
    def meets_target(self) -> bool | None:
        """The issue's target (cumulative error 0 and nothing lost) for redrive chains."""
        if not self.chain.startswith("redrive"):
            return None
        return self.error is None and self.cumulative_error == 0 and self.lost == 0

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        return {
            "chain": self.chain,
            "rate_factor": self.rate_factor,
            "seconds": self.seconds,
            "error": self.error,
            "cumulative_error": self.cumulative_error,
            "lost": self.lost,
            "late": sum(s.late for s in self.streams),
            "meets_target": self.meets_target,
            "streams": [s.to_json(series=series) for s in self.streams],
        }


@dataclass(frozen=True, slots=True, kw_only=True)
class LossBenchResult:
    """Every configuration of one :func:`bench_loss` run, in the order they ran."""

    seconds: float
    configs: tuple[ConfigResult, ...]
    machine: dict[str, str]
    slots: int = SLOTS
    wakeup: dict[str, float] | None = None  # :func:`wakeup_probe` before the first configuration

    def to_json(self, *, series: bool = True) -> dict[str, Any]:
        return {
            "benchmark": "loss",
            "seconds": self.seconds,
            "order": "sequential: for each rate factor, each chain in turn",
            "streams": [
                {"name": s.name, "rate_hz_1x": s.rate_hz, "payload_bytes": s.payload_bytes}
                for s in STREAMS
            ],
            "settings": {
                "sensor_buffer_s": SENSOR_BUFFER_S,
                "legacy_queue_depth": QUEUE_DEPTH,
                "drain_s": DRAIN_S,
                "redrive_slots": self.slots,
            },
            "definitions": {
                "id_diff": "per second: the largest (newest ID due - highest ID received) "
                "over the core's receipts in that second (at the second's end if none)",
                "id_diff_last": "the same at the core's last receipt in the second",
                "cumulative_error": "sum over the seconds of id_diff",
                "lost": "due but never delivered = skipped at the collector (its 1 s buffer "
                "overran) + unsent at the end + lost in transport (handed over, never received)",
                "late": "delivered after the next message of the stream was due",
                "latency": "receipt at the core - due time",
                "collector_delay": "hand-over by the collector - due time",
                "transport": "receipt at the core - hand-over by the collector",
            },
            "machine": dict(self.machine),
            "wakeup_probe": self.wakeup,
            "configurations": [c.to_json(series=series) for c in self.configs],
        }
