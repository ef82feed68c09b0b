"""McapStream: files the mcap library reads with summary, index and CRCs, messages byte for byte;
what a killed writer leaves; the compression thread's back-pressure and failures."""

from __future__ import annotations

import os
import random
import struct
import zlib
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from redrive.io import open_log
from redrive.io.mcap.stream import McapStream, StreamCompression

_CHUNK = 64 << 10


def _messages(seed: int) -> list[tuple[int, int, bytes]]:
    """(channel, log time, data): small ones, a few bigger than a chunk, one empty."""
    rng = random.Random(seed)
    out = []
    for i in range(120):
        size = rng.choice((0, 40, 900, 5000, 30_000, 3 * _CHUNK // 2, 3 * _CHUNK))
        out.append((1 + i % 3, 1_000 + 10 * i + rng.randrange(5), rng.randbytes(size)))
    return out


def _start(
    path: Path, compression: StreamCompression, *, live: bool = False
) -> tuple[int, McapStream]:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    out = McapStream(
        fd, compression=compression, chunk_size_bytes=_CHUNK, queue_chunks=2, live=live
    )
    out.start(profile="ros1", library="redrive-test")
    schema = out.register_schema("std_msgs/String", "ros1msg", b"string data")
    for topic in ("/a", "/b", "/c"):
        out.register_channel(topic, "ros1", schema, {"md5sum": "992ce8a1687cec8c8bd883ec73ca41d1"})
    return fd, out


def _write(
    path: Path, compression: StreamCompression, messages: list[tuple[int, int, bytes]]
) -> int:
    fd, out = _start(path, compression)
    scratch = bytearray(3 * _CHUNK)
    for seq, (channel, log_ns, data) in enumerate(messages):
        # handed over as a view of a buffer that is overwritten right after: the file must
        # hold the bytes as they were during the call
        view = memoryview(scratch)[: len(data)]
        view[:] = data
        out.add_message(channel, log_time=log_ns, publish_time=log_ns + 1, sequence=seq, data=view)
        view[:] = bytes(len(data))
        if seq == 60:
            out.add_metadata("note", {"k": "v"})
    out.finish()
    os.close(fd)
    assert out.uncompressed_chunks == 0  # not live: it waits for the compression thread
    return out.uncompressed_chunks


@pytest.mark.parametrize("compression", ["none", "lz4", "zstd"])
def test_the_mcap_library_reads_it_with_summary_index_and_crcs(
    tmp_path: Path, compression: StreamCompression
) -> None:
    messages = _messages(7)
    path = tmp_path / "out.mcap"
    behind = _write(path, compression, messages)
    expected = [(f"/{'abc'[c - 1]}", t, d) for c, t, d in messages]

    with path.open("rb") as fh:  # every record in file order, chunk and data CRCs checked
        records = list(StreamReader(fh, validate_crcs=True, emit_chunks=True).records)
    assert sum(type(r).__name__ == "Chunk" for r in records) >= 30
    with path.open("rb") as fh:  # through the summary's chunk indexes
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.statistics.message_count == len(messages)
        assert summary.statistics.channel_message_counts == {1: 40, 2: 40, 3: 40}
        assert summary.statistics.metadata_count == 1
        assert len(summary.chunk_indexes) == summary.statistics.chunk_count
        kinds = [i.compression for i in summary.chunk_indexes]
        assert kinds.count("") == (len(kinds) if compression == "none" else behind)
        assert kinds.count(compression) == (0 if compression == "none" else len(kinds) - behind)
        # in file order (chunks the compressor was behind on come before those it still held)
        got = sorted(
            (m.sequence, c.topic, m.log_time, m.data)
            for _, c, m in reader.iter_messages(log_time_order=False)
        )
        assert got == [(i, *m) for i, m in enumerate(expected)]
        by_time = [m.log_time for _, _, m in reader.iter_messages()]
        assert by_time == sorted(t for _, t, _ in messages)
        assert [m.name for m in reader.iter_metadata()] == ["note"]
    # the summary CRC covers the summary and the footer's first fields
    raw = path.read_bytes()
    footer = raw[-8 - 29 : -8]
    _, _, summary_start, offset_start, crc = struct.unpack("<BQQQI", footer)
    assert crc == zlib.crc32(footer[:-4], zlib.crc32(raw[summary_start : len(raw) - 8 - 29]))
    assert summary_start < offset_start
    # redrive's reader too
    with open_log(path) as log:
        assert [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()] == sorted(
            expected, key=lambda m: m[1]
        )


def test_every_finished_chunk_is_on_disk_while_writing(tmp_path: Path) -> None:
    """No user-space buffer: what a writer killed now (SIGKILL) leaves is what the file holds."""
    messages = _messages(3)
    path = tmp_path / "cut.mcap"
    fd, out = _start(path, "none")
    for seq, (channel, log_ns, data) in enumerate(messages[:50]):
        out.add_message(channel, log_time=log_ns, publish_time=log_ns, sequence=seq, data=data)
    assert path.stat().st_size == out.position  # every finished chunk, nothing else
    with open_log(path, strict=False) as log:
        got = [(m.log_time_ns, bytes(m.raw)) for m in log.messages()]
    assert len(got) >= 40  # only the open chunk's messages are missing
    assert got == [(t, d) for _, t, d in messages[: len(got)]]
    os.close(fd)


def test_a_failed_write_in_the_compression_thread_reaches_the_caller(tmp_path: Path) -> None:
    fd, out = _start(tmp_path / "x.mcap", "zstd")
    os.close(fd)  # every write of the thread fails from now on
    with pytest.raises(OSError, match="Bad file descriptor"):  # noqa: PT012  # raised by a later call, whichever
        for seq in range(200):
            out.add_message(1, log_time=seq, publish_time=seq, sequence=seq, data=bytes(3 * _CHUNK))
        out.finish()
    out.abandon()


def _record_behind(
    path: Path, monkeypatch: pytest.MonkeyPatch
) -> tuple[McapStream, list[tuple[int, int, bytes]]]:
    """A live zstd recording whose compressor gets stuck after the first chunk until every
    message is handed over, then finishes: the chunks written meanwhile go to the file
    uncompressed, before the compressed ones that come earlier in time."""
    import threading

    from redrive.io.mcap import stream as mcap_stream

    real = mcap_stream._compressor
    gate = threading.Event()
    calls: list[int] = []

    def held(compression: StreamCompression, *, live: bool, zstd_level: int | None) -> object:
        compress = real(compression, live=live, zstd_level=zstd_level)

        def slow(data: bytes) -> bytes:
            calls.append(len(data))
            if len(calls) > 1:  # the chunk defining the channels passes, then it is stuck
                gate.wait()
            return compress(data)

        return slow

    monkeypatch.setattr(mcap_stream, "_compressor", held)
    messages = _messages(11)
    fd, out = _start(path, "zstd", live=True)
    for seq, (channel, log_ns, data) in enumerate(messages):
        out.add_message(channel, log_time=log_ns, publish_time=log_ns, sequence=seq, data=data)
    assert out.uncompressed_chunks > 0
    gate.set()
    out.finish()
    os.close(fd)
    return out, messages


def test_chunks_the_compressor_cannot_take_are_written_uncompressed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A compressor that is behind (its queue full) never holds up the recording."""
    path = tmp_path / "behind.mcap"
    out, messages = _record_behind(path, monkeypatch)
    with path.open("rb") as fh:
        reader = make_reader(fh, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        kinds = [i.compression for i in summary.chunk_indexes]
        assert kinds.count("") == out.uncompressed_chunks
        assert kinds.count("zstd") >= 3
        got = [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages()]
    assert got == sorted(messages, key=lambda m: m[1])


def test_a_scan_without_summary_restores_time_order_across_chunks_written_out_of_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The recording of a compressor that was behind, killed before its summary: read by a
    forward scan, its messages still come in log-time order, every one of them."""
    from redrive.io.mcap.forward import McapScan

    path = tmp_path / "behind.mcap"
    _, messages = _record_behind(path, monkeypatch)
    data = path.read_bytes()
    # the footer (opcode, length, summary start, summary offset start, crc) before the magic
    (summary_start,) = struct.unpack_from("<Q", data, len(data) - 8 - 29 + 9)
    path.write_bytes(data[:summary_start])  # what a recorder killed after its last chunk leaves
    in_file = [
        item[2]
        for kind, item in McapScan(memoryview(path.read_bytes())).events()
        if kind == "message" and isinstance(item, tuple)
    ]
    assert in_file != sorted(in_file)  # the case at hand: chunks out of time order in the file
    with open_log(path, strict=False) as log:
        got = [(m.log_time_ns, bytes(m.raw)) for m in log.messages()]
    assert got == sorted((t, d) for _, t, d in messages)
