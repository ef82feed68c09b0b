"""``python -m benchmarks all`` (``make bench``): every benchmark once, each in a small documented
configuration and its own process, under a time budget; one markdown summary table.

Each benchmark runs as ``redrive bench NAME … --json`` (the package's own: engine, closed loop)
or ``python -m benchmarks NAME … --json`` (this package's) in a child process with a timeout of its
own; a benchmark that fails, times out or cannot run here (a missing extra, no display) is a row
saying so, never the end of the suite.  The summary lists, per benchmark, the command, its wall
time, and its figures: the targets' min / median / max and verdict where the benchmark reports a
spread over repetitions, otherwise its ratios, speed-ups, rates and real-time factors as found in
its JSON.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["SUITE", "SuiteEntry", "SuiteRow", "run_suite", "summary_markdown"]

#: leaf keys of a benchmark's JSON reported as figures when it gives no spread: a key holding
#: one of these words (``_``-separated), or ending in a rate or a cost per frame
_FIGURE_WORDS = frozenset({"ratio", "speedup", "factor", "fps"})
_FIGURE_ENDINGS = ("_per_s", "_us_per_frame")
_MAX_FIGURES = 6


@dataclass(frozen=True, slots=True, kw_only=True)
class SuiteEntry:
    """One benchmark of the suite: ``args`` after ``redrive bench`` (``redrive=True``) or after
    ``python -m benchmarks`` (``{tmp}`` is a scratch directory of its own), why this
    configuration, its time limit."""

    name: str
    args: tuple[str, ...]
    why: str
    timeout_s: float
    display: bool = False  # needs an X display (run under xvfb-run when there is none)
    redrive: bool = False  # a `redrive bench` command, not one of python -m benchmarks

    @property
    def prefix(self) -> str:
        """What the shown command starts with."""
        return "redrive bench" if self.redrive else "python -m benchmarks"


#: the whole set, in a configuration that takes ~10 minutes on 2 cores (limit: 14.5)
SUITE: tuple[SuiteEntry, ...] = (
    SuiteEntry(
        name="engine",
        args=("engine", "--frames", "1000", "--repeat", "5"),
        why="5 interleaved passes of 1000 frames: the issue's medians of 5",
        timeout_s=150,
        redrive=True,
    ),
    SuiteEntry(
        name="transport",
        args=(
            "transport",
            "--sizes",
            "64K,1M,4M",
            "--seconds",
            "1",
            "--repeat",
            "3",
            "--sides",
            "redrive-copy,redrive-inplace,pipe-pickle,iceoryx2",
        ),
        why="redrive against pipe+pickle and iceoryx2, 1 s per cell, median of 3 repetitions",
        timeout_s=180,
    ),
    SuiteEntry(
        name="read",
        args=("read-synth", "0.1", "--points", "50000", "--repeat", "3", "{tmp}/synth.bag"),
        why="a 0.1 GB synthetic ROS 1 bag of 50k-point sweeps, 3 passes per side",
        timeout_s=120,
    ),
    SuiteEntry(
        name="lidar",
        args=("lidar", "--scans", "20", "--frames", "5"),
        why="20 HDL-32E sweeps and 5 camera frames against Open3D",
        timeout_s=90,
    ),
    SuiteEntry(
        name="closed-loop",
        args=("closed-loop", "--duration", "5", "--repeat", "3"),
        why="5 s of the urban scenario, object level, 3 passes",
        timeout_s=90,
        redrive=True,
    ),
    SuiteEntry(
        name="eval",
        args=("eval", "--frames", "2000", "--repeat", "3"),
        why="2000 frames × 30 boxes, vectorised (3 passes) against the per-frame loop",
        timeout_s=90,
    ),
    SuiteEntry(
        name="batch",
        args=("batch", "--logs", "4", "--duration", "3"),
        why="4 logs of 3 s: 2 local workers against 1, Ray against local",
        timeout_s=120,
    ),
    SuiteEntry(
        name="fleet",
        args=("fleet", "--cells", "40", "--executor", "local"),
        why="40 small logs through the local pool: the driver's memory stays flat",
        timeout_s=60,
    ),
    SuiteEntry(
        name="loss",
        args=("loss", "--seconds", "15", "--out", "{tmp}/loss"),
        why="15 s per rate and chain of the loss experiment (the 30-minute run is its own command)",
        timeout_s=120,
    ),
    SuiteEntry(
        name="record",
        args=("record", "--duration", "8"),
        why="8 s of the KITTI bag looped at 14x: redrive live --record beside rosbag record "
        "(needs ROS 1 and ../shared/data)",
        timeout_s=90,
    ),
    SuiteEntry(
        name="export",
        args=("export", "--duration", "5", "--repeat", "2"),
        why="the Foxglove MCAP export of a 5-s demo run against an mcap copy of its log, 2 passes",
        timeout_s=90,
    ),
    SuiteEntry(
        name="gui",
        args=("gui", "--seconds", "3", "--skip-big"),
        why="3 s of playback per view, small scene only",
        timeout_s=90,
        display=True,
    ),
    SuiteEntry(
        name="serve",
        args=("serve", "--duration", "5"),
        why="redrive serve of a 5-s demo log at 1x to a WebSocket client on loopback: dropped "
        "frames, lag, CPU",
        timeout_s=120,
    ),
)


@dataclass(frozen=True, slots=True, kw_only=True)
class SuiteRow:
    """What one benchmark of the suite did."""

    entry: SuiteEntry
    command: str
    status: str  # ok, failed (exit code N), timeout, skipped (why)
    seconds: float
    figures: tuple[str, ...] = ()
    result: Mapping[str, Any] = field(default_factory=dict)


def _leaves(data: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    if isinstance(data, Mapping):
        for key, value in data.items():
            if key in ("passes", "repetitions", "spread"):
                continue
            yield from _leaves(value, f"{prefix}.{key}" if prefix else str(key))
    else:
        yield prefix, data


def _spreads(data: Any) -> Iterator[Mapping[str, Any]]:
    if isinstance(data, Mapping):
        spread = data.get("spread")
        if isinstance(spread, list):
            yield from (s for s in spread if isinstance(s, Mapping))
        for key, value in data.items():
            if key != "spread":
                yield from _spreads(value)


def _num(value: float) -> str:
    return f"{value:.3g}" if abs(value) < 1000 else f"{value:,.0f}"


def figures(result: Mapping[str, Any]) -> tuple[str, ...]:
    """The figures of one benchmark's JSON worth a summary line each."""
    out = []
    for s in _spreads(result):
        label = " ".join(
            str(s[k]) for k in ("name", "side", "size_bytes") if s.get(k) not in (None, "")
        )
        values = [s.get(k) for k in ("min", "median", "max")]
        if not all(isinstance(v, int | float) for v in values):
            continue
        met = s.get("met")
        verdict = "" if met is None else "meets" if met else "misses"
        target = s.get("target") or (
            f"{'≤' if s.get('at_most') else '≥'} {s['bound']:g}" if "bound" in s else ""
        )
        shown = "/".join(_num(float(v)) for v in values if isinstance(v, int | float))
        out.append(f"{label}: {shown} (min/median/max) {target} {verdict}".strip())
    if out:
        return tuple(out)
    for key, value in _leaves(result):
        last = key.rsplit(".", 1)[-1]
        is_number = isinstance(value, int | float) and not isinstance(value, bool)
        wanted = bool(_FIGURE_WORDS & set(last.split("_"))) or last.endswith(_FIGURE_ENDINGS)
        if is_number and wanted and not last.startswith("target"):
            out.append(f"{key} {_num(float(value))}")
    return tuple(out[:_MAX_FIGURES])


def _command(entry: SuiteEntry, tmp: Path) -> list[str]:
    args = [a.replace("{tmp}", str(tmp)) for a in entry.args]
    head = ["-m", "redrive", "bench"] if entry.redrive else ["-m", "benchmarks"]
    cmd = [sys.executable, *head, *args, "--json"]
    if entry.display and not os.environ.get("DISPLAY") and shutil.which("xvfb-run"):
        cmd = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", *cmd]
    return cmd


def _child_env() -> dict[str, str]:
    """The environment of a child: this one, with the repository root (where ``benchmarks``
    is) and ``src`` ahead on ``PYTHONPATH``."""
    root = Path(__file__).resolve().parents[1]
    paths = [str(root), str(root / "src"), *filter(None, [os.environ.get("PYTHONPATH")])]
    return {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}


def run_one(
    entry: SuiteEntry, *, runner: Callable[..., subprocess.CompletedProcess[str]] | None = None
) -> SuiteRow:
    """Run ``entry`` in a child process under its time limit."""
    run = runner or subprocess.run
    with tempfile.TemporaryDirectory(prefix=f"redrive-bench-{entry.name}-") as tmp:
        cmd = _command(entry, Path(tmp))
        first = cmd.index("bench" if entry.redrive else "benchmarks") + 1
        shown = f"{entry.prefix} " + " ".join(a.replace(tmp, "TMP") for a in cmd[first:])
        if entry.display and not os.environ.get("DISPLAY") and not shutil.which("xvfb-run"):
            return SuiteRow(entry=entry, command=shown, status="skipped (no display)", seconds=0.0)
        t0 = time.perf_counter()
        try:
            proc = run(
                cmd,
                capture_output=True,
                text=True,
                timeout=entry.timeout_s,
                check=False,
                env=_child_env(),
            )
        except subprocess.TimeoutExpired:
            seconds = time.perf_counter() - t0
            return SuiteRow(entry=entry, command=shown, status="timeout", seconds=seconds)
        seconds = time.perf_counter() - t0
    try:
        result = json.loads(proc.stdout) if proc.stdout.strip() else {}
    except json.JSONDecodeError:
        result = {}
    status = "ok" if proc.returncode == 0 else f"failed (exit code {proc.returncode})"
    if proc.returncode != 0 and not result:
        lines = [ln for ln in proc.stderr.strip().splitlines() if ln.strip()]
        if lines:
            status += f": {lines[-1].strip()[:120]}"
    return SuiteRow(
        entry=entry,
        command=shown,
        status=status,
        seconds=seconds,
        figures=figures(result) if isinstance(result, Mapping) else (),
        result=result if isinstance(result, Mapping) else {},
    )


def run_suite(
    entries: Sequence[SuiteEntry] = SUITE,
    *,
    budget_s: float = 870.0,
    progress: Callable[[str], None] | None = None,
    runner: Callable[..., subprocess.CompletedProcess[str]] | None = None,
) -> list[SuiteRow]:
    """Run ``entries`` in order; one whose time limit would pass ``budget_s`` is skipped."""
    rows: list[SuiteRow] = []
    t0 = time.perf_counter()
    for entry in entries:
        left = budget_s - (time.perf_counter() - t0)
        if entry.timeout_s > left:
            rows.append(
                SuiteRow(
                    entry=entry,
                    command=f"{entry.prefix} " + " ".join(entry.args),
                    status=f"skipped (its limit of {entry.timeout_s:g} s would pass the budget)",
                    seconds=0.0,
                )
            )
            continue
        if progress is not None:
            progress(entry.name)
        rows.append(run_one(entry, runner=runner))
    return rows


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def summary_markdown(rows: Sequence[SuiteRow], *, loadavg: str = "", host: str = "") -> str:
    """One markdown table: benchmark, configuration, status, seconds, figures."""
    total = sum(r.seconds for r in rows)
    lines = [
        "# redrive benchmarks: summary",
        "",
        f"{host}; load average before: {loadavg or 'unknown'}; total {total:.0f} s.".lstrip("; "),
        "Verdicts are taken on medians; wall-clock figures on a loaded machine vary (see "
        "BENCHMARKS.md for CPU-time and instruction-count measurements).",
        "",
        "| benchmark | configuration | status | s | figures |",
        "|---|---|---|---:|---|",
    ]
    for r in rows:
        figs = "<br>".join(_cell(f) for f in r.figures) or "—"
        config = f"`{_cell(r.command)}` — {_cell(r.entry.why)}"
        lines.append(
            f"| {r.entry.name} | {config} | {_cell(r.status)} | {r.seconds:.0f} | {figs} |"
        )
    return "\n".join(lines) + "\n"
