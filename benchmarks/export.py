"""``python -m benchmarks export``: the Foxglove MCAP export of the demo run against a plain MCAP copy.

The demo (``redrive synth urban --duration 20``, then ``redrive run`` of it) runs once, in this
process, unless a run is given.  Then, interleaved for each repeat and in this process (the
interpreter and the imports are not timed; the log is read once first so the page cache is warm):

* **export** — :func:`redrive.interop.export_mcap` of the run: the log's chunks copied as they
  are (an MCAP log; other logs re-written), the run's scenes as SceneUpdates and MarkerArrays;
  with ``sensor_copies`` also every LiDAR cloud and camera image converted
  (``foxglove.PointCloud``, JPEG ``foxglove.CompressedImage``).  The previous pass's output is
  deleted before the timer starts (freeing a file's blocks is not the export's work);
* **copy** — the log's messages read and written again with the ``mcap`` library alone (its
  reader, its writer with LZ4 chunks as the export writes them), no decoding, no conversion: the
  floor of any export that reads the log and writes it out.

Reported: seconds (median of the repeats), × real time (the log's span over the seconds), the
ratio export / copy, the same ratio in CPU seconds of the process (less moved by other work on
the machine than the wall clock), and the load average before and after (2 cores are shared here).
"""

from __future__ import annotations

import os
import statistics
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError

__all__ = ["TARGET_REALTIME", "ExportBenchResult", "bench_export", "copy_mcap", "make_demo_run"]

#: issue 18: the export of the 20-s demo run runs at ≥ 20× real time.
TARGET_REALTIME = 20.0


@dataclass(frozen=True, slots=True, kw_only=True)
class ExportBenchResult:
    """One ``bench_export`` run.

    Attributes:
        run: the run exported; log: its log.
        log_span_s: the log's span (first to last message), the real time of the ratios.
        log_bytes, export_bytes, copy_bytes: sizes of the log, the export and the copy.
        export_messages, copy_messages: messages written by each.
        export_s, copy_s: every repeat's wall-clock seconds, in the order run.
        export_cpu_s, copy_cpu_s: the same passes' CPU seconds of this process (user + system,
            every thread): less moved by the machine's other work than the wall clock.
        load_before, load_after: 1-minute load average before the first and after the last pass.
        sensor_copies: the export wrote ``foxglove.PointCloud`` / ``CompressedImage`` copies.
    """

    run: Path
    log: Path
    log_span_s: float
    log_bytes: int
    export_bytes: int
    copy_bytes: int
    export_messages: int
    copy_messages: int
    export_s: tuple[float, ...]
    copy_s: tuple[float, ...]
    export_cpu_s: tuple[float, ...]
    copy_cpu_s: tuple[float, ...]
    load_before: float
    load_after: float
    sensor_copies: bool = False

    @property
    def export_median_s(self) -> float:
        return statistics.median(self.export_s)

    @property
    def copy_median_s(self) -> float:
        return statistics.median(self.copy_s)

    @property
    def cpu_ratio(self) -> float:
        """Export CPU seconds over copy CPU seconds (medians)."""
        copy = statistics.median(self.copy_cpu_s)
        return statistics.median(self.export_cpu_s) / copy if copy > 0 else float("inf")

    @property
    def export_realtime(self) -> float:
        """× real time of the export (median)."""
        return self.log_span_s / self.export_median_s if self.export_median_s > 0 else float("inf")

    @property
    def copy_realtime(self) -> float:
        return self.log_span_s / self.copy_median_s if self.copy_median_s > 0 else float("inf")

    @property
    def ratio(self) -> float:
        """Export seconds over copy seconds (medians): how many copies one export costs."""
        return self.export_median_s / self.copy_median_s if self.copy_median_s > 0 else float("inf")

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["run"], out["log"] = str(self.run), str(self.log)
        out.update(
            export_median_s=self.export_median_s,
            copy_median_s=self.copy_median_s,
            export_realtime=self.export_realtime,
            copy_realtime=self.copy_realtime,
            ratio=self.ratio,
            cpu_ratio=self.cpu_ratio,
        )
        return out


def make_demo_run(workdir: Path, *, duration_s: float = 20.0) -> Path:
    """What ``redrive synth urban -o workdir/urban.mcap --duration D`` then ``redrive run``
    of it into ``workdir/run`` (the reference pipeline) do; returns the run directory."""
    from redrive.config import reference_pipeline
    from redrive.engine import RunRequest, run_log
    from redrive.results import RunStatus
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    log = workdir / "urban.mcap"
    run = workdir / "run"
    synthesize(load_scenario("urban"), log, duration_s=duration_s)
    report = run_log(RunRequest(log=log, pipeline=reference_pipeline(), out=run))
    if report.status is not RunStatus.COMPLETE:
        msg = f"{run}: the demo run ended {report.status.value}; see its manifest.json"
        raise ConfigError(msg)
    return run


def copy_mcap(src: Path, dst: Path) -> int:
    """Every message of ``src`` written to ``dst`` with the ``mcap`` library alone (LZ4 chunks,
    schemas and channels as they are); returns the message count."""
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    count = 0
    with src.open("rb") as fin, dst.open("wb") as fout:
        reader = make_reader(fin)
        writer = Writer(fout, compression=CompressionType.LZ4)
        writer.start()
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            if channel.id not in channels:
                schema_id = 0
                if schema is not None:
                    if schema.id not in schemas:
                        schemas[schema.id] = writer.register_schema(
                            schema.name, schema.encoding, schema.data
                        )
                    schema_id = schemas[schema.id]
                channels[channel.id] = writer.register_channel(
                    channel.topic, channel.message_encoding, schema_id, dict(channel.metadata)
                )
            writer.add_message(
                channels[channel.id],
                log_time=message.log_time,
                data=message.data,
                publish_time=message.publish_time,
                sequence=message.sequence,
            )
            count += 1
        writer.finish()  # type: ignore[no-untyped-call]
    return count


def _message_count(path: Path) -> int:
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    if summary is None or summary.statistics is None:
        return 0
    return int(summary.statistics.message_count)


def _warm(path: Path) -> None:
    with path.open("rb") as f:
        while f.read(16 << 20):
            pass


def bench_export(
    *,
    run: Path | None = None,
    workdir: Path | None = None,
    duration_s: float = 20.0,
    repeats: int = 3,
    sensor_copies: bool = False,
    progress: Callable[[str], None] | None = None,
) -> ExportBenchResult:
    """Time :func:`~redrive.interop.export_mcap` of ``run`` (the demo, made in ``workdir`` or a
    temporary directory, when None) against :func:`copy_mcap` of its log.

    Raises:
        ConfigError: the run's log is not there, or the demo could not be made.
    """
    # imported before any timing: the passes measure the work, not the imports
    import PIL.JpegImagePlugin
    import PIL.PngImagePlugin  # noqa: F401

    from redrive.interop import require_foxglove

    require_foxglove()
    from redrive.interop.mcap_export import export_mcap
    from redrive.interop.stream import find_run_log
    from redrive.io import open_log
    from redrive.results import open_run

    def say(text: str) -> None:
        if progress is not None:
            progress(text)

    with tempfile.TemporaryDirectory(prefix="redrive-bench-export-", dir=workdir) as tmp_name:
        tmp = Path(tmp_name)
        if run is None:
            say(f"making the demo run ({duration_s:g} s of the urban scenario)")
            run = make_demo_run(tmp, duration_s=duration_s)
        log = find_run_log(open_run(run))
        if log is None:
            msg = f"{run}: the run's log is not there; give a run whose log exists"
            raise ConfigError(msg)
        with open_log(log) as reader:
            span_s = (reader.end_ns - reader.start_ns) / 1e9
        _warm(log)
        load_before = os.getloadavg()[0]
        export_s: list[float] = []
        copy_s: list[float] = []
        export_cpu: list[float] = []
        copy_cpu: list[float] = []
        export_path = copy_path = tmp / "none"
        export_messages = copy_messages = 0
        for i in range(repeats):
            say(f"repeat {i + 1}/{repeats}: export")
            export_path.unlink(missing_ok=True)
            t0, c0 = time.perf_counter(), time.process_time()
            export_path = export_mcap(run, out=tmp / "export", sensor_copies=sensor_copies)
            export_s.append(time.perf_counter() - t0)
            export_cpu.append(time.process_time() - c0)
            say(f"repeat {i + 1}/{repeats}: copy")
            copy_path = tmp / "copy.mcap"
            copy_path.unlink(missing_ok=True)
            t0, c0 = time.perf_counter(), time.process_time()
            copy_messages = copy_mcap(log, copy_path)
            copy_s.append(time.perf_counter() - t0)
            copy_cpu.append(time.process_time() - c0)
        load_after = os.getloadavg()[0]
        export_messages = _message_count(export_path)
        return ExportBenchResult(
            run=run,
            log=log,
            log_span_s=span_s,
            log_bytes=log.stat().st_size,
            export_bytes=export_path.stat().st_size,
            copy_bytes=copy_path.stat().st_size,
            export_messages=export_messages,
            copy_messages=copy_messages,
            export_s=tuple(export_s),
            copy_s=tuple(copy_s),
            export_cpu_s=tuple(export_cpu),
            copy_cpu_s=tuple(copy_cpu),
            load_before=load_before,
            load_after=load_after,
            sensor_copies=sensor_copies,
        )
