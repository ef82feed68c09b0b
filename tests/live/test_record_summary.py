"""The closing summary of a record-only session: chunks a compressor could not keep up with."""

from __future__ import annotations

from pathlib import Path

import pytest

from redrive.cli.live_record import _summary
from redrive.live.record import RecordReport
from redrive.live.recording import TopicStatus


def _report(chunks: tuple[int, int]) -> RecordReport:
    status = TopicStatus(
        topic="/cloud", msg_type="sensor_msgs/PointCloud2", recorded=10, recorded_bytes=19_000_000,
        dropped=0, publishers=1,
    )  # fmt: skip
    return RecordReport(
        topics=(status,), files=(Path("rec.mcap"),), wall_s=3.0, reason="Ctrl-C", chunks=chunks
    )


def test_the_summary_says_how_many_chunks_were_written_uncompressed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    _summary(_report((40, 31)))
    out = capsys.readouterr().out
    assert "31 of 40 chunks were written uncompressed" in out
    assert "recorded: rec.mcap" in out
    assert "stopped: Ctrl-C" in out


def test_nothing_is_said_when_every_chunk_was_compressed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    _summary(_report((40, 0)))
    assert "uncompressed" not in capsys.readouterr().out
