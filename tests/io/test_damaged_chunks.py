"""Damaged MCAP chunks lose no more than they must (issue 37): ``repair`` keeps at least what
the readers read, a chunk whose length is damaged is read whole when its CRC passes, and a zstd
chunk that stops decompressing keeps the whole messages before the damage."""

from __future__ import annotations

import logging
import random
from pathlib import Path

import pytest
from mcap.reader import make_reader

from redrive.io import open_log
from redrive.io.repair import repair_log

from ._damage_helpers import write_string_mcap


def _chunks(path: Path) -> list[tuple[int, int]]:
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    assert summary is not None
    return [(c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes]


def _read(path: Path) -> int:
    with open_log(path, strict=False) as log:
        return sum(1 for _ in log.messages())


def test_repair_keeps_what_the_readers_read(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Flipped bytes and lengths, zeroed ranges and cut-out bytes in random chunks: repair writes
    as many messages as open_log(strict=False) yields (it kept 46 of 795 before)."""
    caplog.set_level(logging.ERROR, logger="redrive.io")  # restored after the test
    src = tmp_path / "log.mcap"
    write_string_mcap(src, messages=600)
    original = src.read_bytes()
    chunks = _chunks(src)
    rng = random.Random(37)
    kinds: dict[str, int] = {}
    for _ in range(60):
        data = bytearray(original)
        start, length = chunks[rng.randrange(len(chunks))]
        kind = rng.choice(["flip", "length", "cut", "zero"])
        kinds[kind] = kinds.get(kind, 0) + 1
        if kind == "length":  # the chunk record's length field
            data[start + 1 + rng.randrange(8)] ^= 1 << rng.randrange(8)
        else:
            at = start + rng.randrange(length)
            if kind == "flip":
                data[at] ^= 1 << rng.randrange(8)
            elif kind == "cut":
                del data[at : at + rng.randrange(1, 200)]
            else:
                data[at : at + 64] = bytes(64)
        bad = tmp_path / "bad.mcap"
        bad.write_bytes(bytes(data))
        read = _read(bad)
        stats = repair_log(bad, tmp_path / "fixed.mcap")
        assert stats.messages_written >= read, kind
        assert _read(tmp_path / "fixed.mcap") == stats.messages_written
    assert len(kinds) == 4


def test_a_damaged_chunk_length_is_read_whole(tmp_path: Path) -> None:
    src = tmp_path / "log.mcap"
    original = write_string_mcap(src, messages=300)
    start, _ = _chunks(src)[3]
    data = bytearray(src.read_bytes())
    data[start + 6] ^= 0x40  # the length now runs far past the end of the file
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    with open_log(bad, strict=False) as log:
        got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
        damage = log.damage_report  # type: ignore[attr-defined]
    assert got == original
    assert all(d.messages_lost == 0 for d in damage)
    assert repair_log(bad, tmp_path / "fixed.mcap").messages_written == len(original)


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_a_chunk_that_stops_decompressing_keeps_the_messages_before(
    tmp_path: Path, compression: str
) -> None:
    src = tmp_path / "log.mcap"
    original = write_string_mcap(src, messages=3000, compression=compression, chunk_size=1 << 20)
    ((start, length),) = _chunks(src)  # one chunk of several compressed blocks
    data = src.read_bytes()
    kept = []
    for frac in (0.75, 0.8, 0.85, 0.9, 0.95):
        bad_data = bytearray(data)
        bad_data[start + int(length * frac)] ^= 0xFF
        bad = tmp_path / "bad.mcap"
        bad.write_bytes(bytes(bad_data))
        with open_log(bad, strict=False) as log:
            got = [(m.topic, m.log_time_ns, bytes(m.raw)) for m in log.messages()]
            (damage,) = log.damage_report  # type: ignore[attr-defined]
        assert got == original[: len(got)]  # the messages before the damage, byte for byte
        assert damage.start_byte == start
        assert damage.messages_lost == len(original) - len(got)
        kept.append(len(got))
        if got:
            assert "whole messages" in damage.what
            stats = repair_log(bad, tmp_path / "fixed.mcap")
            assert stats.messages_written == len(got)
    assert max(kept) > 0
