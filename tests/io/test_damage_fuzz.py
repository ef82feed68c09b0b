"""Seeded damaged copies of real and synthetic logs: redrive never crashes on them.

For every log (an MCAP, ROS 1 bags, a ROS 2 bag from ../shared/data, and small synthetic MCAPs of
every compression, chunked or not) and every kind of damage — truncation at many offsets (in the
header, inside a chunk, in the summary or index), bytes flipped inside compressed chunks and
inside record headers, zeroed ranges, a file of only its header — reading (strict and lenient)
raises nothing but redrive's errors, and the lenient read returns every message whose chunk (or
record) lies wholly before the first damaged byte, byte for byte.  Which messages those are is
worked out with the ``mcap`` library and ``rosbags``, not with redrive's readers.  The counts of
damaged files tried and messages recovered are printed (docs/damaged_logs.md records them).
"""

from __future__ import annotations

import io
import os
import random
import shutil
import struct
import subprocess
import sys
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from mcap.data_stream import ReadDataStream
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import breakup_chunk
from rosbags.rosbag1 import Reader as Bag1Reader

from redrive.cli.main import main
from redrive.errors import LogError, RedriveError
from redrive.io import open_log

from ._damage_helpers import write_string_bag, write_string_mcap

Key = tuple[str, int, bytes]
_OPLEN = struct.Struct("<BQ")
_TOTALS: Counter[str] = Counter()


@dataclass
class Layout:
    """A log and where its bytes are: what the oracle needs."""

    path: Path
    kind: str  # mcap, ros1, ros2
    messages: list[tuple[Key, int]]  # (message, byte offset by which it is complete)
    header_end: int  # the end of the file's first record(s): a file of only its header
    chunks: list[tuple[int, int]] = field(default_factory=list)  # (start, end) of chunk data
    record_heads: list[int] = field(default_factory=list)  # offsets of top-level record headers
    tail_start: int = 0  # where the summary / index section starts


def _mcap_layout(path: Path) -> Layout:
    data = path.read_bytes()
    topics: dict[int, str] = {}
    messages: list[tuple[Key, int]] = []
    layout = Layout(path, "mcap", messages, header_end=0)
    pos = 8
    while pos + 9 <= len(data):
        op, length = _OPLEN.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        layout.record_heads.append(pos)
        if op == 0x01:
            layout.header_end = end
        elif op == 0x04:
            channel = Channel.read(ReadDataStream(io.BytesIO(data[body:end])))
            topics[channel.id] = channel.topic
        elif op == 0x05:
            msg = Message.read(ReadDataStream(io.BytesIO(data[body:end])), length)
            messages.append(((topics[msg.channel_id], msg.log_time, bytes(msg.data)), end))
        elif op == 0x06:
            chunk = Chunk.read(ReadDataStream(io.BytesIO(data[body:end])))
            layout.chunks.append((body + 40, end))
            for record in breakup_chunk(chunk):
                if isinstance(record, Channel):
                    topics[record.id] = record.topic
                elif isinstance(record, Message):
                    key = (topics[record.channel_id], record.log_time, bytes(record.data))
                    messages.append((key, end))
        elif op == 0x0F:
            layout.tail_start = end
        elif op == 0x02:
            break
        pos = end
    return layout


def _bag_layout(path: Path) -> Layout:
    with Bag1Reader(path) as reader:
        ends = {pos: c.datapos + c.datasize for pos, c in reader.chunks.items()}
        done: dict[tuple[str, int], int] = {}
        for conn in reader.connections:
            for entry in reader.indexes[conn.id]:
                key = (conn.topic, entry.time)
                done[key] = max(done.get(key, 0), ends[entry.chunk_pos])
        messages = [((c.topic, t, bytes(raw)), done[c.topic, t]) for c, t, raw in reader.messages()]
        chunks = sorted((c.datapos, c.datapos + c.datasize) for c in reader.chunks.values())
        heads = sorted(reader.chunks)  # the chunk records' positions
    layout = Layout(path, "ros1", messages, header_end=heads[0], chunks=chunks)
    layout.record_heads = [13, *heads]  # the bag header record, then every chunk's
    layout.tail_start = chunks[-1][1]
    return layout


def _cases(layout: Layout, rng: random.Random, n: int) -> list[tuple[str, bytes, int]]:
    """(kind, damaged bytes, first damaged byte) — seeded."""
    data = layout.path.read_bytes()
    size = len(data)
    out: list[tuple[str, bytes, int]] = [
        ("header only", data[: layout.header_end], layout.header_end)
    ]
    cuts = [rng.randrange(9, max(10, layout.header_end)) for _ in range(2)]
    cuts += [rng.randrange(a, b) for a, b in rng.sample(layout.chunks, min(n, len(layout.chunks)))]
    cuts += [rng.randrange(layout.tail_start, size) for _ in range(2) if layout.tail_start < size]
    out += [("truncated", data[:c], c) for c in cuts]
    for a, b in rng.sample(layout.chunks, min(n // 2 + 1, len(layout.chunks))):
        at = rng.randrange(a, b)
        out.append(("flipped in a chunk", _flip(data, at, rng), at))
    for head in rng.sample(layout.record_heads, min(n // 2 + 1, len(layout.record_heads))):
        at = head + rng.randrange(0, 9)
        out.append(("flipped in a record header", _flip(data, at, rng), at))
    for _ in range(2):
        at = rng.randrange(layout.header_end, size)
        length = rng.randrange(1, 4096)
        zeroed = data[:at] + bytes(min(length, size - at)) + data[at + length :]
        out.append(("zeroed", zeroed, at))
    return out


def _flip(data: bytes, at: int, rng: random.Random) -> bytes:
    out = bytearray(data)
    for i in range(at, min(at + rng.randrange(1, 16), len(out))):
        out[i] ^= rng.randrange(1, 256)
    return bytes(out)


def _read(path: Path, *, strict: bool) -> list[Key]:
    got: list[Key] = []
    try:
        with open_log(path, strict=strict) as log:
            got.extend((m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages())
    except RedriveError:
        if not strict:
            raise
    return got


def _check(layout: Layout, tmp_path: Path, *, seed: int, n: int) -> None:
    rng = random.Random(seed)
    damaged = tmp_path / f"damaged{layout.path.suffix}"
    for kind, data, first_bad in _cases(layout, rng, n):
        damaged.write_bytes(data)
        try:
            got = _read(damaged, strict=False)
        except RedriveError:
            got = []  # nothing readable at all (a file of only a header, a bad magic)
        wanted = Counter(k for k, end in layout.messages if end <= first_bad)
        missing = wanted - Counter(got)
        assert not missing, f"{kind} at byte {first_bad}: {sum(missing.values())} intact lost"
        if kind in ("truncated", "header only"):  # nothing made up from the bytes of a cut record
            assert not Counter(got) - Counter(k for k, _ in layout.messages), kind
        if rng.random() < 0.3:
            strict = _read(damaged, strict=True)
            assert not Counter(strict) - Counter(got)
        _TOTALS["files"] += 1
        _TOTALS["recovered"] += len(got)
        _TOTALS[f"{layout.kind}: {kind}"] += 1


@pytest.mark.parametrize(
    ("compression", "chunked"), [("zstd", True), ("lz4", True), ("none", True), ("none", False)]
)
def test_synthetic_mcap(tmp_path: Path, compression: str, chunked: bool) -> None:
    src = tmp_path / "log.mcap"
    write_string_mcap(src, messages=200, compression=compression, chunked=chunked)
    seed = ["zstd", "lz4", "none"].index(compression) * 2 + chunked
    _check(_mcap_layout(src), tmp_path, seed=seed, n=6)


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_the_start_of_a_chunk_cut_off_by_the_end_of_the_file_is_read(
    tmp_path: Path, compression: str
) -> None:
    """A recorder killed while writing a chunk: the whole messages of its start are read (zstd
    and lz4 frames give their complete blocks), in order, none made up; the rest is reported."""
    src = tmp_path / "one_chunk.mcap"
    sent = write_string_mcap(src, messages=6000, compression=compression, chunk_size=1 << 22)
    data = src.read_bytes()
    (chunk_at, chunk_end) = _mcap_layout(src).chunks[0]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: chunk_at + (chunk_end - chunk_at) * 7 // 10])
    with open_log(cut, strict=False) as log:
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
        (damage,) = [d for d in log.damage_report if "inside a chunk" in d.what]
    assert 0 < len(got) < len(sent)
    assert got == sent[: len(got)]  # the chunk's first messages, in order
    assert f"{len(got)} whole messages of its start were read" in damage.what


def test_real_mcap(shared_data: Path, tmp_path: Path) -> None:
    layout = _mcap_layout(shared_data / "rosbag_fixtures/evo_nav2_turtlebot_sim.mcap")
    _check(layout, tmp_path, seed=19, n=6)


@pytest.mark.parametrize("compression", ["bz2", "lz4", "none"])
def test_synthetic_ros1_bag(tmp_path: Path, compression: str) -> None:
    src = tmp_path / "log.bag"
    write_string_bag(src, compression=compression)
    _check(_bag_layout(src), tmp_path, seed=len(compression), n=6)


def test_real_ros1_bag(shared_data: Path, tmp_path: Path) -> None:
    _check(_bag_layout(shared_data / "rosbag_fixtures/evo_tf_example.bag"), tmp_path, seed=5, n=6)


def test_real_ros2_bag(shared_data: Path, tmp_path: Path) -> None:
    """sqlite keeps rows on pages in no file order: no "before the damage" to check, but every
    message read is one of the bag's and nothing but redrive's errors escapes."""
    src = shared_data / "rosbag_fixtures/evo_tf_example_ros2"
    with open_log(src) as log:
        original = Counter((m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages())
    bag = tmp_path / "bag"
    shutil.copytree(src, bag)
    db = next(bag.glob("*.db3"))
    data = db.read_bytes()
    rng = random.Random(2)
    for at in sorted(rng.sample(range(100, len(data)), 8)):
        db.write_bytes(data[:at])
        try:
            got = _read(bag, strict=False)
        except LogError:  # the database's first pages (its schema) are gone: nothing is readable
            got = []
        assert not Counter(got) - original
        _read(bag, strict=True)
        _TOTALS["files"] += 1
        _TOTALS["recovered"] += len(got)
        _TOTALS["ros2: truncated"] += 1


def test_cli_on_damaged_logs_prints_no_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = tmp_path / "log.mcap"
    write_string_mcap(src, messages=100)
    data = src.read_bytes()
    (tmp_path / "cut.mcap").write_bytes(data[: len(data) // 2])
    (tmp_path / "head.mcap").write_bytes(data[:40])
    done = subprocess.run(  # one real process: what a user sees, exit status included
        [sys.executable, "-m", "redrive", "info", "cut.mcap"],
        cwd=tmp_path,
        env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2] / "src")},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 5, done.stderr
    assert "Traceback" not in done.stdout + done.stderr
    assert "damaged" in done.stdout
    for args in (
        ["info", str(tmp_path / "head.mcap")],
        ["info", "--strict", str(tmp_path / "cut.mcap")],
    ):
        status = main(args)
        out = capsys.readouterr()
        assert status == (1 if "--strict" in args else 5)
        assert "Traceback" not in out.out + out.err


def test_zz_print_counts() -> None:
    """Runs last in this module: the counts the docs quote."""
    print(f"\ndamaged files tried: {_TOTALS['files']}, messages recovered: {_TOTALS['recovered']}")
    for key, count in sorted(_TOTALS.items()):
        if ":" in key:
            print(f"  {key}: {count}")
