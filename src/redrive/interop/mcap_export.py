"""``redrive export RUN --format mcap``: a run over its log as one MCAP for Foxglove and RViz.

The file holds the :class:`~redrive.interop.stream.SceneStream` of the run (its channels are
listed there), written through ``foxglove-sdk``'s MCAP writer (``foxglove.open_mcap`` on a
context of its own, LZ4 chunks, CRCs, summary with statistics and indexes).  LZ4, not zstd:
on the demo log it wrote 4.5× faster than single-threaded zstd (0.25 s against 1.14 s for a
second of log) for a file 30 % larger.  It is written next
to its place and renamed into it, so a stopped export leaves no half file.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path

import foxglove
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from redrive.interop.stream import SceneStream, open_scene_stream

__all__ = ["export_mcap", "write_stream"]

logger = logging.getLogger(__name__)


def write_stream(
    stream: SceneStream, path: Path, *, progress: Callable[[int], None] | None = None
) -> int:
    """Write every message of ``stream`` to a new MCAP at ``path``; returns the message count.

    ``progress`` is called with each message's log time (ns)."""
    context = foxglove.Context()
    tmp = path.with_name(f".{path.name}.part")
    count = 0
    try:
        with foxglove.open_mcap(
            tmp,
            allow_overwrite=True,
            context=context,
            writer_options=MCAPWriteOptions(compression=MCAPCompression.Lz4),
        ):
            channels = {
                topic: foxglove.Channel(
                    topic,
                    schema=foxglove.Schema(
                        name=spec.schema_name, encoding=spec.schema_encoding, data=spec.schema_data
                    ),
                    message_encoding=spec.message_encoding,
                    context=context,
                    metadata=dict(spec.metadata),
                )
                for topic, spec in stream.channels.items()
            }
            for message in stream.messages():
                channels[message.topic].log(message.data, log_time=message.log_time_ns)
                count += 1
                if progress is not None:
                    progress(message.log_time_ns)
            for channel in channels.values():
                channel.close()
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return count


def export_mcap(run_dir: Path, *, out: Path, progress: Callable[[int], None] | None = None) -> Path:
    """Write ``out/<run name>.mcap`` (``out`` created): the run's log and results for Foxglove.

    Raises:
        LogError, ConfigError: the run or its log cannot be read.
    """
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"{run_dir.resolve().name or 'run'}.mcap"
    with open_scene_stream(run_dir) as stream:
        count = write_stream(stream, path, progress=progress)
    logger.info("exported %s for Foxglove: %d messages in %s", run_dir, count, path)
    return path
