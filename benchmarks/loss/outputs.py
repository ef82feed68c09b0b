"""The outputs of a run: ``loss.json``, ``loss.png`` (the paper's Figures 10/11) and
``loss_table.md`` (its Table 5)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from benchmarks.loss.results import LossBenchResult

__all__ = ["plot_loss", "table_markdown", "write_outputs"]


def _ms(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{x:.1f}" if x >= 10 else f"{x:.2f}"


def table_markdown(result: LossBenchResult) -> str:
    """The Table-5-like table: one row per stream and configuration, a total per configuration."""
    lines = [
        "| configuration | stream | Hz | due | delivered | lost (skipped at collector / unsent "
        "at end / in transport) | late | **cumulative error** (Σ ID difference) | max ID "
        "difference | latency p50 / p99 / max ms | p99 ms collector / transport |",
        "|---|---|---:|---:|---:|---|---:|---:|---:|---|---|",
    ]
    for c in result.configs:
        if c.error is not None:
            lines.append(f"| {c.label} | failed: {c.error.splitlines()[0]} |||||||||")
            continue
        for s in c.streams:
            lines.append(
                f"| {c.label} | {s.name} | {s.rate_hz:g} | {s.due:,} | {s.delivered:,} | "
                f"{s.lost:,} ({s.skipped_at_collector:,} / {s.unsent_at_end:,} / "
                f"{s.lost_in_transport:,}) | {s.late:,} | {s.cumulative_error:,} | "
                f"{s.max_id_diff:,} | {_ms(s.latency_p50_ms)} / {_ms(s.latency_p99_ms)} / "
                f"{_ms(s.latency_max_ms)} | {_ms(s.collector_delay_p99_ms)} / "
                f"{_ms(s.transport_p99_ms)} |"
            )
        late = sum(s.late for s in c.streams)
        due = sum(s.due for s in c.streams)
        got = sum(s.delivered for s in c.streams)
        lines.append(
            f"| **{c.label}** | **all** | | {due:,} | {got:,} | **{c.lost:,}** | {late:,} | "
            f"**{c.cumulative_error:,}** | | | |"
        )
    return "\n".join(lines) + "\n"


def plot_loss(result: LossBenchResult, path: Path) -> None:
    """The paper's Figures 10/11: ID difference per second, one panel per chain and rate factor
    (a line per stream), and the cumulative error over time of every chain per rate factor."""
    from matplotlib.figure import Figure

    factors = list(dict.fromkeys(c.rate_factor for c in result.configs))
    chains = list(dict.fromkeys(c.chain for c in result.configs))
    fig = Figure(figsize=(4.2 * (len(chains) + 1), 3.0 * len(factors)), layout="constrained")
    axes = fig.subplots(len(factors), len(chains) + 1, squeeze=False)
    for c in result.configs:
        row = factors.index(c.rate_factor)
        ax = axes[row][chains.index(c.chain)]
        cum = axes[row][-1]
        if c.error is not None:
            ax.set_title(f"{c.label}: failed", fontsize=9)
            continue
        total = np.zeros(len(c.streams[0].id_diff), np.int64)
        edges = np.arange(total.size + 1)
        for s in c.streams:
            ax.stairs(s.id_diff, edges, lw=0.9, label=f"{s.name} ({s.rate_hz:g} Hz)")
            total += np.asarray(s.id_diff)
        ax.set_title(
            f"{c.label}: cumulative error {c.cumulative_error:,}, lost {c.lost:,}", fontsize=9
        )
        ax.set_xlabel("time (s)")
        ax.set_ylabel("ID difference (collector − core)")
        ax.set_ylim(bottom=0, top=max(1.0, float(total.max()) * 1.05))
        ax.legend(fontsize=7, loc="upper left")
        cum.plot(edges[1:], np.cumsum(total), lw=1.0, label=c.chain)
        cum.set_yscale("symlog", linthresh=1.0)
        cum.set_ylim(bottom=0, top=max(10.0, 2.0 * cum.get_ylim()[1]))
        cum.set_title(f"{c.rate_factor:g}×: cumulative error (all streams)", fontsize=9)
        cum.set_xlabel("time (s)")
        cum.legend(fontsize=7, loc="upper left")
    fig.savefig(path, dpi=110, format="png")


def write_outputs(result: LossBenchResult, out_dir: Path) -> dict[str, Path]:
    """``loss.json`` (everything, with the per-second series), ``loss.png`` and ``loss_table.md``
    in ``out_dir`` (created); returns their paths by kind."""
    import json

    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {
        "json": out_dir / "loss.json",
        "png": out_dir / "loss.png",
        "table": out_dir / "loss_table.md",
    }
    for kind, write in (
        ("json", lambda p: p.write_text(json.dumps(result.to_json(), indent=1) + "\n")),
        ("png", lambda p: plot_loss(result, p)),
        ("table", lambda p: p.write_text(table_markdown(result))),
    ):
        tmp = paths[kind].with_name(paths[kind].name + ".tmp")
        write(tmp)
        tmp.replace(paths[kind])
    return paths
