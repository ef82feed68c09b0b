"""McapStream splicing small MCAP files written by the ``mcap`` library: copied chunks stay byte for
byte, rewritten chunks lose only the channel left out, a summary-less log is not spliced, and a
summary that does not match the file is an error that says what to do."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from redrive.errors import LogError
from redrive.interop.mcap_splice import chunk_messages, read_layout
from redrive.io.mcap.stream import McapStream

Row = tuple[str, int, int, int, bytes]


def _log(path: Path, *, chunked: bool = True) -> None:
    """/a (ros2msg schema) and /b (no schema): 60 messages in 4-KiB zstd chunks."""
    with path.open("wb") as f:
        w = Writer(f, chunk_size=4096, compression=CompressionType.ZSTD, use_chunking=chunked)
        w.start(profile="ros2", library="test")
        schema = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        a = w.register_channel("/a", "cdr", schema, {"k": "v"})
        b = w.register_channel("/b", "json", 0)
        for i in range(60):
            w.add_message(
                a if i % 3 else b,
                log_time=1_000 + 10 * i,
                publish_time=2_000 + i,
                sequence=i,
                data=bytes([i % 251]) * (100 + 37 * i),
            )
        w.finish()  # type: ignore[no-untyped-call]


def _rows(path: Path) -> list[Row]:
    with path.open("rb") as f:
        return [
            (c.topic, m.log_time, m.publish_time, m.sequence, m.data)
            for _, c, m in make_reader(f).iter_messages(log_time_order=True)
        ]


def _linear(path: Path) -> list[tuple[int, int, int, int, bytes]]:
    from mcap.records import Message

    with path.open("rb") as f:
        return sorted(
            (r.channel_id, r.log_time, r.publish_time, r.sequence, r.data)
            for r in StreamReader(f).records
            if isinstance(r, Message)
        )


def _splice(src: Path, dst: Path, *, drop: set[int], extra: list[tuple[int, bytes]]) -> None:
    layout = read_layout(src)
    assert layout is not None
    new_id = max(layout.channels) + 1
    with src.open("rb") as fin, dst.open("wb") as fout:
        out = McapStream(fout.fileno(), compression="lz4", chunk_size_bytes=1024)
        out.start(profile="", library="test")
        for schema in layout.schemas.values():
            out.add_schema(schema)
        for channel in layout.channels.values():
            if channel.id not in drop:
                out.add_channel(channel)
        out.add_schema(Schema(id=99, name="x.Y", encoding="jsonschema", data=b"{}"))
        out.add_channel(
            Channel(id=new_id, topic="/new", message_encoding="json", schema_id=99, metadata={})
        )
        pending = list(extra)
        for index in layout.chunks:
            while pending and pending[0][0] < index.message_start_time:
                t, data = pending.pop(0)
                out.add_message(new_id, log_time=t, publish_time=t, sequence=0, data=data)
            if drop & set(index.message_index_offsets):
                messages = chunk_messages(fin.fileno(), index, where=str(src))
                for cid, seq, log_time, publish_time, data in messages:
                    if cid not in drop:
                        out.add_message(
                            cid,
                            log_time=log_time,
                            publish_time=publish_time,
                            sequence=seq,
                            data=data,
                        )
                out.end_chunk()
            else:
                out.copy_chunk(fin.fileno(), index, where=str(src))
        for t, data in pending:
            out.add_message(new_id, log_time=t, publish_time=t, sequence=0, data=data)
        out.finish()


def test_copied_chunks_and_new_messages_read_back_in_log_time_order(tmp_path: Path) -> None:
    src, dst = tmp_path / "log.mcap", tmp_path / "out.mcap"
    _log(src)
    layout = read_layout(src)
    assert layout is not None
    assert len(layout.chunks) > 3
    extra = [(995 + 40 * k, b'{"k": %d}' % k) for k in range(20)]
    _splice(src, dst, drop=set(), extra=extra)
    got = _rows(dst)
    assert [r for r in got if r[0] != "/new"] == _rows(src)
    assert [(r[1], r[4]) for r in got if r[0] == "/new"] == extra
    assert [r[1] for r in got] == sorted(r[1] for r in got)
    # the chunk records are the log's bytes
    data, out = src.read_bytes(), dst.read_bytes()
    for index in layout.chunks:
        chunk = data[index.chunk_start_offset : index.chunk_start_offset + index.chunk_length]
        assert chunk in out
    with dst.open("rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None
        assert summary.statistics is not None
        assert summary.statistics.message_count == 80
        assert len(list(reader.iter_messages())) == 80
    with dst.open("rb") as f:
        indexed = sorted(
            (c.id, m.log_time, m.publish_time, m.sequence, m.data)
            for _, c, m in make_reader(f).iter_messages()
        )
    assert indexed == _linear(dst)


def test_a_channel_left_out_is_removed_from_the_rewritten_chunks(tmp_path: Path) -> None:
    src, dst = tmp_path / "log.mcap", tmp_path / "out.mcap"
    _log(src)
    layout = read_layout(src)
    assert layout is not None
    b = next(c.id for c in layout.channels.values() if c.topic == "/b")
    _splice(src, dst, drop={b}, extra=[])
    assert _rows(dst) == [r for r in _rows(src) if r[0] != "/b"]
    with dst.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert "/b" not in {c.topic for c in summary.channels.values()}


def test_a_log_without_chunk_index_is_not_spliced(tmp_path: Path) -> None:
    src = tmp_path / "flat.mcap"
    _log(src, chunked=False)
    assert read_layout(src) is None
    (tmp_path / "not.mcap").write_bytes(b"\x89MCAP0\r\n" + b"\0" * 20)
    assert read_layout(tmp_path / "not.mcap") is None


def test_a_summary_that_does_not_match_the_file_says_repair(tmp_path: Path) -> None:
    src = tmp_path / "log.mcap"
    _log(src)
    layout = read_layout(src)
    assert layout is not None
    index = layout.chunks[1]
    index.chunk_start_offset += 3  # the summary points beside the chunk
    fd = os.open(tmp_path / "out.mcap", os.O_WRONLY | os.O_CREAT)
    try:
        with src.open("rb") as fin, pytest.raises(LogError, match="redrive repair"):
            McapStream(fd, compression="none").copy_chunk(fin.fileno(), index, where=str(src))
    finally:
        os.close(fd)
